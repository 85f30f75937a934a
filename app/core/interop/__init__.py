"""Formats and conventions of other tools: Kalibr, EuRoC CSV, MCAP (ROS 2), ENU/NED."""
