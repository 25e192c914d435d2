"""Onboard SLAM: occupancy grids, beam traversal, scan matching (pure numpy/numba)."""
