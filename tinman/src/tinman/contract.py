"""TinMan's contract in its report: each time and value constraint of the protocol, as the roles saw it.

The protocol states the control period, the answers' deadlines, the sensors' rates, Move's patience
for poses and scans, and the velocity limits (tinman.proto). The monitors check them on every send
and receive and count, per constrained interaction, how often they checked it and how close it came
to its time bound (:class:`anodize.EndpointStatistics`' ``constraints``). Each role leaves that in
its record (:func:`contract_of`); the report puts the records together, one entry per interaction
and side (:func:`contract_report`), with any violation and whom it blames.
"""

from __future__ import annotations

from typing import Any

from anodize import DeadlineMissedError, Endpoint, ProtocolViolationError, RunReport

__all__ = ["contract_of", "contract_report", "contract_lines", "contract_violations"]


def contract_of(ep: Endpoint) -> dict[str, dict[str, Any]]:
    """Per constrained interaction of ``ep``'s role (with its parallel branches), how many times its
    constraints were checked and the closest margin to a time bound (ms; None without one)."""
    return {key: {"checked": check.checked,
                  "closest_ms": None if check.closest_ns is None else round(check.closest_ns / 1e6, 3)}
            for key, check in ep.statistics().constraints.items()}


def _split(role: str, key: str) -> tuple[str, str, str]:
    """``!Move(Twist) within 100ms {...}`` at Control as (interaction, constraints, side):
    ``("Control -> Move: Twist", "within 100ms {...}", "sends")``."""
    arrow, rest = key[0], key[1:]
    opening = rest.find("(")
    depth, end = 0, len(rest)
    for index in range(opening, len(rest)):
        depth += {"(": 1, ")": -1}.get(rest[index], 0)
        if depth == 0:
            end = index
            break
    peer, message, constraints = rest[:opening], rest[opening + 1:end], rest[end + 1:].strip()
    if arrow == "!":
        return f"{role} -> {peer}: {message}", constraints, "sends"
    return f"{peer} -> {role}: {message}", constraints, "receives"


def contract_report(records: dict[str, dict[str, Any]], report: RunReport) -> list[dict[str, Any]]:
    """The contract section of ``report.json``: one entry per constrained interaction and side
    (the sender checks periods, deadlines and values; the receiver deadlines and values), with
    the timeouts Move took and the violations, each on the side whose monitor raised it (the
    sender's for a refused send, the receiver's for a deadline that passed), with whom it blames."""
    violations = contract_violations(report)
    move = records.get("Move", {})
    timeouts = {"VisOdom -> Move": move.get("estimate_timeouts"), "Gazebo -> Move": move.get("scan_timeouts")}
    entries = []
    for role, record in sorted(records.items()):
        contract = record.get("contract")
        if not isinstance(contract, dict):
            continue
        for key, check in sorted(contract.items()):
            if not isinstance(key, str) or key[:1] not in ("!", "?") or not isinstance(check, dict):
                continue
            interaction, constraints, side = _split(role, key)
            pair = interaction.split(":")[0]
            blamed = [v for v in violations if v["interaction"] == pair and v["raised_at"] == role]
            entries.append({"interaction": interaction, "constraints": constraints, "checked_by": role,
                            "side": side, "checked": check.get("checked"), "closest_ms": check.get("closest_ms"),
                            "timeouts": timeouts.get(pair) if side == "receives" and "else timeout" in constraints
                            else None,
                            "violations": blamed, "held": not blamed})
    return entries


def contract_violations(report: RunReport) -> list[dict[str, Any]]:
    """Every violation of a constraint the monitors raised: the interaction, whom it blames, why."""
    found = []
    for name, role in report.roles.items():
        error = role.error
        if not isinstance(error, ProtocolViolationError):
            continue
        reason = str(error)
        if not isinstance(error, DeadlineMissedError) and "refinement" not in reason:
            continue
        peer = error.peer or (error.actual.peer if error.actual is not None else None) or "?"
        sender, receiver = (name, peer) if _sends(error) else (peer, name)
        found.append({"interaction": f"{sender} -> {receiver}", "raised_at": name, "blame": error.blame,
                      "message": reason})
    return found


def _sends(error: ProtocolViolationError) -> bool:
    """Whether the refused action was the raising role's send."""
    return error.actual is not None and error.actual.kind == "send"


def contract_lines(contract: list[dict[str, Any]]) -> list[str]:
    """The contract as the printed report's lines, one per constrained interaction and side."""
    lines = []
    for entry in contract:
        closest = entry["closest_ms"]
        margin = f", closest margin {closest:.1f} ms" if isinstance(closest, (int, float)) else ""
        timeouts = entry.get("timeouts")
        took = (f", {timeouts:,} timeout{'s' if timeouts != 1 else ''} taken" if isinstance(timeouts, int) and timeouts
                else "")
        verdict = "held" if entry["held"] else "VIOLATED: " + "; ".join(
            f"blamed on {v['blame']}: {v['message']}" for v in entry["violations"])
        constraints = entry["constraints"]
        lines.append(f"contract: {entry['interaction']} {constraints}: {entry['checked']:,} {entry['side']} "
                     f"checked by {entry['checked_by']}{margin}{took}, {verdict}")
    return lines
