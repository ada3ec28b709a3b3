"""Systems, groups, transports and the supervisor (the paper's primordial thread).

:class:`System` declares groups and runs them on a transport value (:class:`Inproc`,
:class:`Processes`, :class:`Dds`); one supervision core applies failure policies,
keeps run and group state, samples status and builds the :class:`RunReport`,
whichever transport carries the messages.
"""

from .group import Group
from .report import GroupReport, GroupStatus, RoleReport, RunReport
from .rosbridge import RosBridge
from .system import System
from .transports import Dds, Inproc, Processes, Transport, Zenoh

__all__ = ["System", "Group", "RunReport", "RoleReport", "GroupReport", "GroupStatus", "Inproc", "Processes", "Dds",
           "Zenoh", "RosBridge", "Transport"]
