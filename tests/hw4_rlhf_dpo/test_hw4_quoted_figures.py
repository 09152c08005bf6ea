"""hw4's section 5.4 quotes the benchmark's over-optimisation runs: each figure it gives is the recorded one."""
from __future__ import annotations

import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "bench/results/hw4_rlhf_dpo.json"
NOTEBOOKS = [REPO / "solutions/hw4_rlhf_dpo/hw4_rlhf_dpo.ipynb", REPO / "assignments/hw4_rlhf_dpo/hw4_rlhf_dpo.ipynb"]


def _section_5_4(path: Path) -> str:
    cells = json.loads(path.read_text())["cells"]
    text = next("".join(c["source"]) for c in cells if "".join(c["source"]).startswith("### 5.4"))
    return re.sub(r"\s+", " ", text)


def test_the_offset_paragraph_quotes_the_recorded_runs():
    """With b = 1 the true return moved (it ended above the reference's and peaked higher): the paragraph
    gives those figures, and the final returns of b = 5, from ``summary.overoptimisation``."""
    runs = json.loads(RESULTS.read_text())["summary"]["overoptimisation"]
    low = runs["b = 1, no KL"]
    start, end, peak = low["return"][0], low["return"][-1], max(low["return"])
    want = [f"to {runs['b = 5, KL 0.03']['return'][-1]:,.0f} and {runs['b = 5, no KL']['return'][-1]:,.0f} "
            f"from the reference's {start:,.0f}",
            f"({low['learned_return'][0]:,.0f} → {low['learned_return'][-1]:,.0f})",
            f"ended at {end:,.0f}, {end / start - 1:.0%} above the reference's ({peak:,.0f}, or {peak / start - 1:.0%}, "
            "at its best)"]
    for path in NOTEBOOKS:
        text = _section_5_4(path)
        for figure in want:
            assert figure in text, f"{path.relative_to(REPO)}: section 5.4 should say {figure!r}"
