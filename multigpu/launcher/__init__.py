"""The launcher's side: the code that never runs under MPI. Choosing the MPI and starting the job
on its hosts (remote shells, host checks), supervising it, recovery by relaunch, the operator's
view on a PC of its own, the host's leftover shared segments."""
