"""Pure per-frame math: camera matrices, object bounds to screen rects, the GPU tree, the
strip balancer and its split choosers, pixel regions and transfer plans, draw lists.
Imports neither moderngl nor mpi4py: everything here tests in one process.
"""
