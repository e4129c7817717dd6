"""The parametric bike in Gaussian space: the 8-DoF pose maths (pose.py), the model that poses
part Gaussians and keypoints (model.py), `pose-bike` (command.py), the library contact sheet."""
