"""Virtual-robot-motion map merging (pure numpy/scipy/skimage/numba)."""
