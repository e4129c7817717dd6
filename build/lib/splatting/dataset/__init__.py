"""Synthetic COCO training data (`python -m splatting dataset`): config, sampling, COCO writer."""
