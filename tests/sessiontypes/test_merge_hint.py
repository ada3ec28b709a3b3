"""An unmergeable choice's error ends with the usual fix, in the file's own syntax, and the fix works."""

from __future__ import annotations

import re

import pytest

import sessiontypes
from sessiontypes import ProtocolCheckError, ProtocolError

UNINFORMED = """global Deal(A, B, C) =
  A -> B : {
    buy(). B -> C : ship(str),
    cancel()
  }
"""


def _error(text: str, path: str) -> ProtocolError:
    with pytest.raises(ProtocolError) as caught:
        sessiontypes.loads(text, path)
    return caught.value


def test_the_error_suggests_that_the_chooser_tells_the_role() -> None:
    lines = str(_error(UNINFORMED, "deal.proto")).splitlines()
    assert lines[0].startswith("deal.proto:2:3: error: global Deal is not projectable onto role C: ")
    assert lines[1:3] == ["      A -> B : {", "      ^"]  # the place, as before
    assert lines[3] == ("    hint: C must learn which branch A chose before it acts differently: in each branch, "
                        "have A send C a message first, e.g. `A -> C : buy()` in branch 'buy' and "
                        "`A -> C : cancel()` in branch 'cancel'")


def test_following_the_hint_makes_the_protocol_projectable() -> None:
    hint = str(_error(UNINFORMED, "deal.proto")).splitlines()[3]
    buy, cancel = re.findall(r"`A -> C : (\w+\(\))`", hint)
    fixed = UNINFORMED.replace("buy(). ", f"buy(). A -> C : {buy}. ")
    fixed = fixed.replace("cancel()\n", f"cancel(). A -> C : {cancel}\n")
    module = sessiontypes.loads(fixed, "deal.proto")
    assert str(module.globals["Deal"].project("C")) == "&A{buy.?B(ship(str)), cancel}"


def test_a_scribble_file_is_told_in_scribble() -> None:
    text = ("global protocol P(role A, role B, role C) {\n choice at A { x() from A to B; y() from B to C; } "
            "or { z() from A to B; }\n}")
    error = _error(text, "p.scr")
    assert isinstance(error, ProtocolCheckError)
    assert str(error).splitlines()[-1] == (
        "    hint: C must learn which branch A chose before it acts differently: in each branch, have A send C a "
        "message first, e.g. `x() from A to C;` in branch 'x' and `z() from A to C;` in branch 'z'")


def test_a_routed_choice_with_one_label_twice_gets_two_names() -> None:
    text = "global P(A, B, C) = A -> { B : x(). B -> C : done(), C : x() }\n"
    hint = str(_error(text, "p.proto")).splitlines()[-1]
    assert "`A -> " in hint and "B_x()" in hint and "C_x()" in hint
