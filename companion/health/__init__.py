"""Gyro health: baseline of healthy noise coefficients and the degradation test (numpy/scipy only)."""
