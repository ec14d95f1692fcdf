"""The MPI edge: the job's lifecycle (liveness, interrupts, exit), frame exchange, the
rank's frame loop in named phases, outputs (timing rows, summary, mosaics), the launcher.
"""
