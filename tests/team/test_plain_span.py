"""A batch's span per source (``semwm.sources.plain_span``): its fast path (float times,
one source, no Python code per detection) gives what the loop over detections gives, to
the object: the same earliest and latest time (the first of equal ones: -0.0 and 0.0),
the same count, and ``None`` where the loop says the batch is not plain."""

from __future__ import annotations

import math
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from semwm.detection import Detection
from semwm.sources import _span_each, plain_span

times = st.one_of(
    st.sampled_from([0.0, -0.0, 1.5, math.inf, -math.inf, math.nan, 1e308, 1, True, "1.0"]),
    st.floats(-1e3, 1e3),
)
detections = st.one_of(
    st.fixed_dictionaries({"time": times, "source": st.sampled_from([None, "r1", "r2"])}),
    st.fixed_dictionaries({"time": times}),  # no source at all: the same as None
)


@given(st.lists(detections, max_size=6))
def test_the_fast_path_gives_what_the_loop_gives(batch: list[dict[str, Any]]) -> None:
    assert repr(plain_span(batch)) == repr(_span_each(batch))


def test_the_common_batch_and_what_is_not_plain() -> None:
    batch = [
        {"time": 2.0, "source": "r1"},
        {"time": -0.0, "source": "r1"},
        {"time": 0.0, "source": "r1"},
    ]
    span = plain_span(batch)
    assert span == {"r1": [-0.0, 2.0, 3]} and math.copysign(1.0, span["r1"][0]) == -1.0
    assert plain_span([]) == {}
    assert plain_span([{"time": math.inf}]) is None
    assert (
        plain_span([Detection.model_validate({"time": 1.0, "class": "Cup", "position": [0, 0]})])
        is None
    )
