"""How messages travel between roles.

- :mod:`.inproc`: one queue per channel, between threads of one process;
- :mod:`.network`: the channels of one group's process, composed of local queues and
  one transport's links (:mod:`.links` says what a transport provides):
  - :mod:`.process`: between group processes, frames of :mod:`.codec` (no pickle for
    known sorts; :mod:`.pickle_guard` for the classes that do travel pickled) in a
    shared-memory byte ring per channel (:mod:`.ring`), an OS pipe to wake a sleeping
    receiver and tell it of its sender's death, and large numpy arrays in the
    shared-memory slots of :mod:`.shm`;
  - :mod:`.dds`: DDS topics on Cyclone DDS, the binding reached only through
    :mod:`.dds.binding`;
  - :mod:`.zenoh`: Zenoh key expressions (peers or clients of routers), the binding
    reached only through :mod:`.zenoh.binding`.

Each gives one FIFO channel per ordered pair of roles the global type connects,
and carries a peer's failure or a stop after everything sent before it.
"""
