"""A seeded sample of the fuzzer's cases (tests/fuzzing.py; benchmarks/fuzz.py runs 100,000+).

Every mutated real file is read or refused with one clear MocapInputError: no other exception, no
warning on the terminal, no case over 5 s or over the memory bound. Blender's import operator on
such files: tests/blender/test_fuzz_blender.py.
"""

from __future__ import annotations

import fuzzing
import pytest

SEEDS = fuzzing.load_seeds()
MASTER_SEED = 35


def _seeds():
    if not SEEDS:
        pytest.skip(f"real data not available: {fuzzing.DATA}")
    return SEEDS


@pytest.mark.slow
def test_a_seeded_sample_of_mutated_real_files_reads_or_is_refused_cleanly(tmp_path):
    seeds = _seeds()
    cuts = len(fuzzing.truncations(seeds))
    sample = [*fuzzing.cases(seeds, cuts, MASTER_SEED, step=12),  # every 12th truncation
              *fuzzing.cases(seeds, 1800, MASTER_SEED, systematic=False)]
    tally = fuzzing.Tally()
    for case in sample:
        tally.add(case, fuzzing.run_case(case, tmp_path))
    assert tally.cases >= 2000
    assert not tally.failures, "\n".join(f"{label}: {detail}" for label, detail in tally.failures[:20])
    # Both outcomes occur, for every format: the sample exercises the readers, not only their first check.
    for ext in ("c3d", "trc", "tsv"):
        counts = {k: sum(c.get(k, 0) for kind, c in tally.by_kind.items() if kind.startswith(ext))
                  for k in ("read", "error")}
        assert counts["read"] > 20 and counts["error"] > 20, (ext, counts)
