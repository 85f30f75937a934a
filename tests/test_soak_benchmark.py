"""benchmarks/soak.py still runs: 3 s of the simulator recorded and accounted for."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_soak_script_accounts_for_every_sample(tmp_path: Path) -> None:
    out = tmp_path / "soak.json"
    result = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "soak.py"), "--mode", "sim",
         "--minutes", "0.05", "--rss-every", "0.5", "--dir", str(tmp_path),
         "--json", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "SILENT LOSS" in result.stdout
    figures = json.loads(out.read_text())
    counts = figures["counts"]
    assert counts["received"] > 0
    assert counts["received"] == counts["recorded"] == counts["read_back"]
    assert figures["unmarked_holes"] == 0
    assert figures["rss"] and all(row["rss_mb"] for row in figures["rss"])
