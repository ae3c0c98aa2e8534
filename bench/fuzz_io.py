"""Fuzz the readers with byte mutations for a long budget (issue 11) and print, per format,
the mutants tried and how their decodes ended: decoded, one-line errors, crashes and hangs of
the decoder (contained by the child process), and anything else ("bad", which must be 0).

    python bench/fuzz_io.py                      # EVSTWIN_FUZZ_EXAMPLES or 2000 mutants per file
    python bench/fuzz_io.py --examples 5000 --seed 3 --timeout 5 --save-dir /tmp/fuzz-findings

Every decode runs in a child process (also for the formats decoded in the process by default)
so that a crash or a hang is seen; a crash or hang of such a format (npz, txt, csv) would take a
user's process down and is reported as FAIL. Mutants that crashed, hung or were bad are saved
with --save-dir to reproduce them.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from pathlib import Path

from evstwin.io import _fuzzing, _isolation


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=int(os.environ.get("EVSTWIN_FUZZ_EXAMPLES", "2000")),
                        help="mutants per file (default: EVSTWIN_FUZZ_EXAMPLES or 2000)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the mutations (default 1)")
    parser.add_argument("--timeout", type=float, default=5.0,
                        help="seconds without progress before a decode counts as hung (default 5)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 2, help="decodes at a time (default: CPUs)")
    parser.add_argument("--save-dir", type=Path, default=None, help="keep crashing/hanging/bad mutants here")
    args = parser.parse_args()
    if args.examples < 1:
        parser.error(f"--examples must be >= 1; got {args.examples}")
    counts: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    slowest: dict[str, float] = collections.defaultdict(float)
    examples: dict[tuple[str, str], str] = {}
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="evstwin-fuzz-") as tmp:
        work = Path(tmp)
        files = _fuzzing.write_samples(work, Path(__file__).resolve().parents[1] / "tests" / "data")
        for k, r in enumerate(_fuzzing.run(files, args.examples, work, args.seed, args.timeout, args.workers)):
            counts[r.label][r.outcome] += 1
            if r.outcome != "hang":
                slowest[r.label] = max(slowest[r.label], r.seconds)
            if r.outcome in ("crash", "hang", "bad"):
                examples.setdefault((r.label, r.outcome), r.message)
                if args.save_dir is not None:
                    args.save_dir.mkdir(parents=True, exist_ok=True)
                    suffix = files[r.label].suffix
                    (args.save_dir / f"{r.outcome}-{r.label.split()[0]}-{k}{suffix}").write_bytes(r.mutant)
    elapsed = time.perf_counter() - start
    print(f"{args.examples} mutants per file, seed {args.seed}, timeout {args.timeout:g} s, {elapsed:.0f} s")
    header = f"{'file':24} {'isolated':>8} {'mutants':>8} {'ok':>7} {'errors':>7} {'crashes':>8} {'hangs':>6} {'bad':>4} {'slowest s':>9}"
    print(header)
    failed = False
    for label, c in counts.items():
        fmt = {".h5": "hdf5", ".npz": "npz", ".txt": "txt", ".csv": "csv", ".aedat4": "aedat4",
               ".raw": "raw", ".dat": "dat", ".es": "es"}[files[label].suffix]
        isolated = fmt in _isolation.ISOLATED
        failed = failed or c["bad"] > 0 or (not isolated and c["crash"] + c["hang"] > 0)
        print(f"{label:24} {'yes' if isolated else 'no':>8} {sum(c.values()):8d} {c['ok']:7d} {c['error']:7d} "
              f"{c['crash']:8d} {c['hang']:6d} {c['bad']:4d} {slowest[label]:9.2f}")
    for (label, outcome), message in sorted(examples.items()):
        print(f"  first {outcome} of {label}: {message[:160]}")
    print("FAIL" if failed else "PASS: every decode ended in a result or a one-line ValueError/OSError; "
          "crashes and hangs only in isolated decoders")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
