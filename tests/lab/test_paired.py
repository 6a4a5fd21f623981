"""Proofs for Table I's paired comparison (``python -m lab.bench.paired``)."""

import json

import pytest

from lab.bench import paired


def _write(folder, name, domain, condition, cds, f1s):
    shapes = [{"shape_seed": 1_000_000 + k, "cd_l1_x100": cd, "cd_l2": 0.0, "f1_0.005": f1}
              for k, (cd, f1) in enumerate(zip(cds, f1s))]
    (folder / f"{name}_{domain}_{condition}.json").write_text(json.dumps({"shapes": shapes}))


def test_differences_are_per_shape_and_count_where_learned_is_better(tmp_path):
    _write(tmp_path, "ours-learned", "cars", "noisy", [0.30, 0.31, 0.40, 9.0], [0.90, 0.80, 0.7, 0])
    _write(tmp_path, "ours-r0.03", "cars", "noisy", [0.32, 0.30, 0.41, 0.0], [0.85, 0.85, 0.6, 0])
    found = paired.paired(tmp_path, 3, "best fixed", "cars", "noisy")
    mean, error, better = found["cd_l1_x100"]
    assert mean == pytest.approx((-0.02 + 0.01 - 0.01) / 3)
    assert better == 2  # a lower CD is better
    assert error == pytest.approx((((-0.02 - mean) ** 2 + (0.01 - mean) ** 2
                                    + (-0.01 - mean) ** 2) / 2 / 3) ** 0.5)
    mean, _, better = found["f1_0.005"]
    assert mean == pytest.approx((0.05 - 0.05 + 0.1) / 3) and better == 2  # a higher F1 is


def test_too_few_shapes_is_an_error(tmp_path):
    _write(tmp_path, "ours-learned", "rooms", "clean", [0.2, 0.2], [0.9, 0.9])
    _write(tmp_path, "poisson", "rooms", "clean", [0.3, 0.3], [0.8, 0.8])
    with pytest.raises(SystemExit, match="2 shapes, not 3"):
        paired.paired(tmp_path, 3, "poisson", "rooms", "clean")
