"""Bad input through the real command line (docs/reliability.md): exit 2, one line, nothing written.

The inputs are the rows of ``scripts/reliability_inputs.py``, run by ``scripts/reliability_table.py``
(which writes docs/reliability.md);
the default run takes a sample covering every kind (overrides, unknown keys, Hydra's schema
errors, destination paths and free space, a user's garden file and species presets), the slow
run all of them.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("reliability_table", REPO / "scripts" / "reliability_table.py")
table = sys.modules.setdefault("reliability_table", importlib.util.module_from_spec(_spec))
_spec.loader.exec_module(table)  # registered first: its dataclasses look their module up

SAMPLE = {
    "typo in a section (tress)",
    "turbidity beyond the sky model",
    "string for an integer",
    "dataset under /proc",
    "job larger than the free disk",
    "unknown key in the file",
    "out-of-range value in the file",
    "tree: word for a number (Levels: two)",
}
CASES = [
    pytest.param(case, id=case.label, marks=() if case.label in SAMPLE else pytest.mark.slow)
    for case in table.BAD_INPUTS
]


def test_the_table_has_at_least_50_inputs_and_the_sample_covers_every_kind():
    assert len(table.BAD_INPUTS) >= 50
    labels = {case.label for case in table.BAD_INPUTS}
    assert SAMPLE <= labels and len(labels) == len(table.BAD_INPUTS)
    assert {case.kind for case in table.BAD_INPUTS if case.label in SAMPLE} == {case.kind for case in table.BAD_INPUTS}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return table.Inputs(tmp_path_factory.mktemp("inputs"))


@pytest.mark.parametrize("case", CASES)
def test_bad_input_stops_before_any_work(case, inputs, tmp_path):
    result = table.run_bad_input(case, tmp_path / "job", inputs)
    assert result.run.rc == 2, result.run.stderr[-3000:]
    assert result.run.lines == [result.run.message] and result.run.message.startswith("eden-pipe: ")
    for word in case.words:
        assert word in result.run.message, (word, result.run.message)
    assert result.written == [], "bad input must not create any file or folder"
