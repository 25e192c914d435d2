"""Worlds, experiment definitions, the experiment runner and the ``mrslam`` CLI."""
