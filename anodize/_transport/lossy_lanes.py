"""Which ROS topics may lose messages: those whose protocol can lose one without changing any role's state.

A message that is sent but never received moves its sender on and leaves its receiver
where it was. The run stays in step only if "where it was" is where the receiver would
have been anyway: every receive of that label from that sender, in every state and
parallel branch of the receiver's machine, must lead back to the state it starts from
(a self-loop), as a stream does: ``mu s. Gazebo -> Move : LaserScan. s``. Then the
receiver's next action does not depend on how many of those messages arrived, its
monitor accepts any number of them, and the sender's state never depended on them.

Two more things a loss must not do: move the receiver's lane plan (which topic it
reads next, :mod:`.ros_lanes`) -- a self-loop in the machine is one in the plan only
if the plan's own step is one too; and pass a receive deadline with no ``else timeout``,
which the monitor would report as a deadline the sender missed.
"""

from __future__ import annotations

from collections.abc import Mapping

from sessiontypes import StateMachine
from sessiontypes.fsm import Transition

from .qos_profiles import QosError, QosProfile

__all__ = ["check_lossy"]


def check_lossy(machine: StateMachine, sender: str, receiver: str, label: str, topic: str, profile: QosProfile,
                key: str, plan_steps: Mapping[tuple[int, str], int] | None = None) -> None:
    """Refuse a lossy ``profile`` on the topic carrying ``label`` from ``sender`` into ``receiver``
    (whose machine is ``machine``) unless losing one of its messages changes no role's state.
    ``plan_steps``: the steps of the channel's lane plan, where it has one.

    Raises:
        QosError: naming the interaction that makes a loss unsafe, where it is written, and why.
    """
    if not profile.lossy:
        return
    lossy = f"{topic} is {profile.describe()} and may lose messages, but"
    for branch in machine.with_branches():
        for state, actions in enumerate(branch.table):
            transition = actions.get(("recv", sender, label))
            if transition is None:
                continue
            where = _where(transition, sender, receiver, label)
            if transition.target != state:
                raise QosError(key, f"{lossy} {where} moves {receiver} on to its next step: a lost {label} would "
                                    f"leave {receiver} waiting for it while {sender} has gone on. Only a message whose "
                                    f"every receive leaves its receiver where it was (a stream: mu s. {sender} -> "
                                    f"{receiver} : {label}. s) may be lost; give this topic a reliable keep_all QoS")
            timing = transition.timing
            if timing is not None and timing.within is not None and not timing.on_expiry:
                raise QosError(key, f"{lossy} {where} has a deadline (within) with no 'else timeout': a lost {label} "
                                    f"would be reported as a deadline {sender} missed; write 'else timeout' there, "
                                    "or give this topic a reliable keep_all QoS")
    if plan_steps is not None:
        for (number, step_label), target in plan_steps.items():
            if step_label == label and target != number:
                raise QosError(key, f"{lossy} on channel {sender}->{receiver} the topic {receiver} reads next "
                                    f"changes after {label}: a lost {label} would leave {receiver} reading the wrong "
                                    "topic; give this topic a reliable keep_all QoS")



def _where(transition: Transition, sender: str, receiver: str, label: str) -> str:
    return f"{sender} -> {receiver} : {label} (at {transition.location})"
