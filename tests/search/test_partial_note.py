"""What a search's answer says of a single view: how much of it the fittest match holds,
against the share its own object's surface holds."""

from __future__ import annotations

import pytest

from app.search.service import PartialQuery
from worker.engine.rigid import HELD_FITNESS


def view_note(held: float) -> str:
    return PartialQuery(0.5, 0.5, (0.4, 0.6), single_view=True, cloud=True, verified=15,
                        held=held).note  # fmt: skip


@pytest.mark.parametrize(
    ("held", "says"),
    [
        (HELD_FITNESS - 3e-4, "holds 89.9% of it, under the 90%"),
        (HELD_FITNESS, "holds 90.0% of it, at least 90%"),
        (0.912, "holds 91.2% of it, at least 90%"),
        (0.243, "holds 24.3% of it, under the 90%"),
        (0.95, "holds 95.0% of it, at least 90%"),  # 1000 x 0.95 is 949.99999999999989
    ],
)
def test_the_fittest_match_s_share_is_never_rounded_up_to_the_bar(held, says):
    """A share just under the bar is not printed as the bar itself ("holds 90.0% of it,
    under the 90%", as the code before said of 89.97%)."""
    assert says in view_note(held)
