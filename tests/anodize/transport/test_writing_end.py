"""The read side every transport's sending end shares: a read there is a mistake, named."""

from __future__ import annotations

import pytest

from anodize._transport.links import WritingEnd
from anodize._transport.process import PipeSender
from anodize._transport.zenoh.ros_external import ExternalSender
from anodize.errors import AnodizeError


class _End(WritingEnd):
    """A sender of a transport that keeps the default: its receiver's group reads the channel."""


@pytest.mark.parametrize(("end", "where"), [
    (_End, "in VisOdom's group"), (PipeSender, "in VisOdom's process"), (ExternalSender, "by a ROS 2 node")])
def test_reading_a_writing_end_names_the_channel_and_where_it_is_read(end: type[WritingEnd], where: str) -> None:
    writing = end.__new__(end)  # the read side needs only the channel's names
    writing.sender, writing.receiver = "Camera", "VisOdom"
    assert writing.empty()
    for read in (writing.get, writing.get_nowait):
        with pytest.raises(AnodizeError) as raised:
            read()
        assert str(raised.value) == f"the channel Camera->VisOdom is read {where}"
