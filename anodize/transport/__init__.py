"""How messages travel between roles.

- :mod:`.inproc`: one queue per channel, between threads of one process;
- :mod:`.process`: OS pipes between group processes, framed by :mod:`.codec`
  (no pickle for known sorts), with large numpy arrays in the shared-memory
  rings of :mod:`.shm`.

Each gives one FIFO channel per ordered pair of roles the global type connects,
and carries a peer's failure or a stop after everything sent before it.
"""
