"""The material panel's widget values: imgui hands back float32s; what is edited and saved is the shortest decimal
of the same float32 (0.3 typed is 0.3 in the saved document, not 0.30000001192092896)."""
from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from nbrdf.viewer.ui.material_widgets import typed


def test_a_typed_value_is_saved_as_typed():
    assert [typed(np.float32(x)) for x in (0.3, 0.45, 1e-5, 1.0, 0.08)] == [0.3, 0.45, 1e-5, 1.0, 0.08]
    assert repr(typed(float(np.float32(0.3)))) == "0.3"


@given(st.floats(-1e6, 1e6, allow_nan=False, width=32))
def test_the_value_is_the_same_float32(v: float):
    assert np.float32(typed(v)) == np.float32(v)
