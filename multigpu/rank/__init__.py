"""A rank's side: the code that runs under MPI, one process per tile, and the only package that
imports mpi4py. The job's lifecycle (liveness, interrupts, exit), setup, the frame loop in named
phases with its frames in flight, the exchange backends and compositing, live input and
steering, each rank's tile."""
