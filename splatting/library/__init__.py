"""The asset library as one resumable command (`python -m splatting library build`), its
manifest (library.json) and the engines that run it and the datasets (local pool or Ray).

    manifest     task records, file hashes, library.json, quality floors
    tasks        the task kinds: bike views, part training, posed fine-tune, ground-truth check, rider avatar
    gt           the ground-truth check: composed Gaussian bike vs Blender at fixed random poses
    engine       run a task graph on a local pool or on Ray
    command      the `library build` command line
    use          what datasets accept from the library (trained, usable assets only)
    dataset_ray  dataset samples as Ray tasks over index ranges
"""
