"""The composition root: worlds, the end-to-end experiment, the `mrslam` CLI and benchmarks."""
