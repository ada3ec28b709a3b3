"""Systems, groups and the supervisor (the paper's primordial thread).

:class:`System` declares groups and runs them; one supervision core applies
failure policies, keeps run and group state, samples status and builds the
:class:`RunReport`, whichever transport carries the messages.
"""

from .group import Group
from .report import GroupReport, GroupStatus, RoleReport, RunReport
from .system import System

__all__ = ["System", "Group", "RunReport", "RoleReport", "GroupReport", "GroupStatus"]
