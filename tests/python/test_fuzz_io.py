"""Byte-mutation fuzzing of every reader (issue 11): flips, truncations and splices of a small
file of each format evstwin writes and of the real cuts in tests/data. Each decode runs in a
child process (for every format, so a crash or hang is observed) and must end in events or a
one-line ValueError/OSError naming the file; a crash or hang is only allowed where the format
is decoded in a child anyway (it is then a one-line error for the user).

A few hundred mutants in all by default; ``EVSTWIN_FUZZ_EXAMPLES=N`` sets the total (e.g. 20000
for a long run; ``bench/fuzz_io.py`` prints the figures per format).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from evstwin.io import _fuzzing, _isolation

pytest.importorskip("aedat")
pytest.importorskip("faery")

DATA = Path(__file__).resolve().parents[1] / "data"  # the repository's, whatever evstwin is installed as
TOTAL = int(os.environ.get("EVSTWIN_FUZZ_EXAMPLES", "330"))
LABELS = ["hdf5", "npz", "txt", "csv", "aedat4", "raw evt3", "raw evt2", "dat", "es", *_fuzzing.REAL_CUTS]
FORMAT = {".h5": "hdf5", ".npz": "npz", ".txt": "txt", ".csv": "csv", ".aedat4": "aedat4",
          ".raw": "raw", ".dat": "dat", ".es": "es"}


@pytest.fixture(scope="module")
def samples(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return _fuzzing.write_samples(tmp_path_factory.mktemp("fuzz-samples"), DATA)


@pytest.mark.parametrize("label", LABELS)
def test_mutated_files_end_in_events_or_one_line_errors(
    samples: dict[str, Path], tmp_path: Path, label: str
) -> None:
    assert samples[label].is_file(), samples[label]  # the real cuts are in the repository: never skipped
    examples = max(1, TOTAL // len(LABELS))
    results = list(_fuzzing.run({label: samples[label]}, examples, tmp_path, seed=0, timeout_s=5.0))
    assert len(results) == examples
    bad = [(r.kind, r.message) for r in results if r.outcome == "bad"]
    assert not bad, f"{len(bad)} decodes ended otherwise than in events or a one-line error: {bad[:3]}"
    if FORMAT[samples[label].suffix] not in _isolation.ISOLATED:  # decoded in the caller's process
        fatal = [(r.kind, r.message) for r in results if r.outcome in ("crash", "hang")]
        assert not fatal, f"would take the process down: {fatal[:3]}"
    outcomes = {r.outcome for r in results}
    assert "error" in outcomes  # the mutations do reach the decoders
    assert list(tmp_path.iterdir()) == []


def test_mutations_are_seeded_and_of_every_kind() -> None:
    import random

    data = random.Random(0).randbytes(2048)
    a = [_fuzzing.mutate(data, random.Random(f"7:{k}")) for k in range(60)]
    b = [_fuzzing.mutate(data, random.Random(f"7:{k}")) for k in range(60)]
    assert a == b
    assert {kind for kind, _ in a} == set(_fuzzing.KINDS)
    assert sum(mutant != data for _, mutant in a) >= 58  # a splice may copy a span onto itself
