"""Simulator: pymunk world, robots, lidar, odometry, peer sensor, comm link (pymunk only here)."""
