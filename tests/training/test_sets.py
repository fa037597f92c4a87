"""The look-development sets: a validation set beside the test set, same classes, no shared material."""
from __future__ import annotations

from nbrdf.neural.material import material_to_dict
from nbrdf.training.render_report import SETS_DIR, load_set


def _body(m) -> dict:
    d = material_to_dict(m)
    d.pop("name", None)
    return d


def test_validation_set_covers_the_test_classes_and_shares_no_material():
    test, val = load_set("lookdev"), load_set(str(SETS_DIR / "lookdev_val"))
    assert len(val) >= 10
    assert {c for c, _ in val} == {c for c, _ in test} == {"coated_diffuse", "car_paint", "coated_metal"}
    bodies = [_body(m) for _, m in test]
    assert not [m.name for _, m in val if _body(m) in bodies]
    assert not {m.name for _, m in val} & {m.name for _, m in test}
