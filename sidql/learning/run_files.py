"""What a training run writes besides its checkpoint: the policy (OUT), the evaluation log
(OUT.csv) and the learning curve (OUT.png), all atomically (:class:`RunFiles`).
"""

from __future__ import annotations

import csv
import io
from dataclasses import asdict, dataclass
from pathlib import Path

from sidql.learning.files import POLICY_FORMAT, save_payload
from sim.files import write_atomic


def save_policy(net, path, args, split, final, baselines) -> None:
    """Write the policy (weights, network config, training args, held-out figures) atomically."""
    payload = {
        "format": POLICY_FORMAT,
        "config": dict(net.config),
        "state_dict": {k: v.clone() for k, v in net.state_dict().items()},
        "keyframe_counts": list(args.keyframe_counts),
        "args": {k: v for k, v in asdict(args).items() if k != "extra"},
        "split": split,
        "heldout": {"dqn": final, **baselines},
    }
    save_payload(path, payload)


def write_log(rows: list[dict], path: Path) -> None:
    """The evaluation log as CSV, atomically."""

    def write(f):
        text = io.StringIO()
        w = csv.DictWriter(text, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        f.write(text.getvalue().encode())

    write_atomic(path, write)


def plot_curve(rows: list[dict], keyframes, path: Path) -> None:
    """Held-out mean Q / optimal per W over the run (dashed: greedy), as PNG."""
    import matplotlib  # lazy: heavy and only needed here

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy, after choosing the headless backend

    fig, ax = plt.subplots(figsize=(6, 3.6))
    steps = [r["step"] for r in rows]
    for w, color in zip(keyframes, ("C0", "C1", "C2", "C3", "C4", "C5"), strict=False):
        opt = rows[-1][f"optimal_W{w}"]
        ax.plot(steps, [r[f"dqn_W{w}"] / opt for r in rows], color=color, label=f"dqn W={w}")
        ax.axhline(rows[-1][f"greedy_W{w}"] / opt, color=color, ls="--", lw=0.8)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("held-out mean Q / optimal")
    ax.set_title("DQN learning curve (dashed: greedy)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=110))
    plt.close(fig)


def log_row(counters: dict, seconds: float, epsilon: float, loss: float, q_mean: float,
            heldout: dict[int, float], base: dict, keyframes) -> dict:  # fmt: skip
    """One line of the log: counters, time, ε, mean loss and Q since the last line, and the
    held-out mean Q of the network, greedy and the optimum for every W."""
    row = {**counters, "seconds": round(seconds, 1), "epsilon": round(epsilon, 4), "loss": loss,
           "q_mean": q_mean}  # fmt: skip
    for w in keyframes:
        row[f"dqn_W{w}"] = heldout[w]
        row[f"greedy_W{w}"] = base["greedy"][w]
        row[f"optimal_W{w}"] = base["optimal"][w]
    return row


@dataclass(frozen=True)
class RunFiles:
    """What a run writes: ``policy`` (OUT), ``checkpoint`` (OUT.ckpt), ``log`` (.csv), ``curve``
    (.png)."""

    policy: Path
    checkpoint: Path
    log: Path
    curve: Path

    @classmethod
    def beside(cls, out: str | Path) -> RunFiles:
        out = Path(out)
        return cls(out, out.with_name(out.name + ".ckpt"), out.with_suffix(".csv"),
                   out.with_suffix(".png"))  # fmt: skip


def record(files: RunFiles, log_rows: list[dict], row: dict, keyframes) -> None:
    """Append ``row`` to the log and rewrite the CSV and the learning curve."""
    log_rows.append(row)
    write_log(log_rows, files.log)
    plot_curve(log_rows, keyframes, files.curve)
