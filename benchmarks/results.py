"""Results tables written by the benchmark that measures them.

Every figure the docs show lives in ``docs/results/<name>.md``, written here by the benchmark that
measured it, with the command that reproduces it and the date; the docs pages link to (or include)
these files and never retype a figure, so no two pages can disagree.

Usage inside a benchmark::

    from results import write_results
    write_results("ingest", "Ingest throughput", table_markdown, command="python benchmarks/bench_ingest.py")
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.files import write_atomic  # noqa: E402

RESULTS_DIR = Path(__file__).resolve().parents[1] / "docs" / "results"


def machine() -> str:
    """One line naming the machine a figure was measured on (cores, load)."""
    try:
        load = os.getloadavg()[0]
        load_text = f", load average {load:.1f} at the end"
    except OSError:
        load_text = ""
    return f"{platform.machine()}, {os.cpu_count()} cores{load_text}"


def write_results(name: str, title: str, markdown: str, command: str, notes: str = "") -> Path:
    """Write ``docs/results/<name>.md`` atomically: a title, the command, the date, the table.

    ``markdown`` is the body (tables, short prose); ``command`` is what a reader runs to regenerate
    the file. Returns the path written.
    """
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    date = _dt.date.today().isoformat()
    text = (
        f"# {title}\n\n"
        f"<!-- written by {command}; do not edit by hand -->\n"
        f"Measured {date} on {machine()} by:\n\n```bash\n{command}\n```\n\n"
        f"{markdown.rstrip()}\n"
    )
    if notes:
        text += f"\n{notes.rstrip()}\n"
    path = RESULTS_DIR / f"{name}.md"
    write_atomic(path, lambda f: f.write(text.encode()))
    return path


def keep_rows(page: str, rows: list[dict], suffix: str = "") -> str:
    """Keep the per-clip rows a page was written from beside it, as JSON lines in
    ``docs/results/rows/<page><suffix>.jsonl`` (atomically), so the page can be written again
    from the repository alone and a later run can pair against them. Returns the path
    relative to the repository root, as the page's regenerating command names it."""
    import json

    path = RESULTS_DIR / "rows" / f"{page}{suffix}.jsonl"
    body = "".join(json.dumps(row, sort_keys=True) + "\n" for row in rows).encode()
    write_atomic(path, lambda f: f.write(body), root=RESULTS_DIR)
    return str(path.relative_to(RESULTS_DIR.parents[1]))


def load_trials(data, min_frames: int = 60) -> tuple[list, list[str]]:
    """Every trial under ``data`` read by ``load_motion`` (30 fps clips, MuJoCo forward
    kinematics): ``(clips, skipped)``, where ``skipped`` names each trial left out and why (it does
    not parse, or it is shorter than ``min_frames`` frames)."""
    from sim.errors import MotionDataError
    from sim.motion.dataset import find_trials
    from sim.motion.ingest import load_motion

    clips, skipped = [], []
    for trial in find_trials(data):
        name = Path(trial.amc).name
        try:
            clip = load_motion(trial.asf, trial.amc)
        except MotionDataError as e:
            skipped.append(f"{name}: {e.problem}")
            continue
        if clip.n_frames < min_frames:
            skipped.append(f"{name}: {clip.n_frames} frames < {min_frames}")
            continue
        clips.append(clip)
    return clips, skipped
