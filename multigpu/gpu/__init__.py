"""The GL edge: the one place that creates contexts (moderngl on EGL), region rendering,
depth-complexity measurement.
"""
