"""Training part Gaussians on rendered views: the views folder (views.py), targets cropped per view
(targets.py), the initial Gaussians (initialisation.py), the loop (trainer.py),
densification strategies (strategy.py), image metrics (metrics.py), the command (command.py)."""
