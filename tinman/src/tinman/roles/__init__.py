"""TinMan's roles, one module per group of the system file ``tinman/tinman.toml``.

Every role is a plain ``def role(ep: Endpoint) -> None`` that talks only through
its monitored endpoint. The same functions run both global types: under
``TinManParallel`` the roles in two loops (VisOdom, Move) fork one thread per
loop; under the paper's ``TinMan`` they take each step in the single loop's order.
"""
