"""Policy and checkpoint files: tensors and plain values only, with a format version.

A file is one ``torch.save`` of a dict whose ``"format"`` entry names its kind and version
(:data:`POLICY_FORMAT`, :data:`sidql.learning.checkpoint.CHECKPOINT_FORMAT`). Loading uses
``torch.load(weights_only=True)``, which rebuilds only tensors and plain Python values (dict,
list, tuple, str, int, float, bool, None) and refuses any other pickled object *before*
constructing it, so a crafted file cannot run code. Anything refused, unreadable or of another format raises
:class:`sim.errors.ModelFileError` (the CLI prints one line and exits 2).
"""

from __future__ import annotations

import io
import os
import pickle
import re
import warnings
import zipfile

import torch

from sim.errors import ModelFileError, MotionDataError, UsageError
from sim.files import MAX_CHECKPOINT_BYTES, excerpt, open_regular, write_atomic
from sim.zipcheck import check_zip

#: Kind and version of a trained policy file (``sidql train``'s OUT, ``sidql/data/policy.pt``).
#: Version 2: the head's layers are named modules (``adv_hidden``, ``adv_out``, ``value_hidden``,
#: ``value_out``).
POLICY_FORMAT = "sidql-dqn-policy/2"
#:

#: Stated limits of a policy or checkpoint archive, checked on its zip directory before
#: ``torch.load`` reads anything: members (one per tensor storage, plus a few) and the size of
#: its pickle (the values other than tensors: settings, logs; a few KB in real files).
MAX_ARCHIVE_MEMBERS = 4096
MAX_PICKLE_BYTES = 4 << 20


def check_archive(f, path: str) -> None:
    """Check the zip directory of a ``torch.save`` file ``f`` before it is loaded, then rewind.

    ``torch.save`` stores every member uncompressed, so a file inflates to no more than its own
    size: a compressed member (a deflate bomb), overlapping members, more than
    :data:`MAX_ARCHIVE_MEMBERS` members or a pickle larger than :data:`MAX_PICKLE_BYTES` is
    refused.

    Raises:
        ModelFileError: one line naming the file and the problem.
    """
    size = os.fstat(f.fileno()).st_size
    try:
        with zipfile.ZipFile(f) as zf:
            infos = check_zip(
                zf, size, path, max_members=MAX_ARCHIVE_MEMBERS, max_inflated=size,
                stored_only=True,
            )  # fmt: skip
    except zipfile.BadZipFile as e:
        raise ModelFileError(
            path, None, f"refused: not a file of tensors (a torch.save zip archive): {e}"[:200]
        ) from None
    except MotionDataError as e:
        raise ModelFileError(path, None, f"refused: {e.problem}") from None
    pickles = [i for i in infos if i.filename.endswith("data.pkl")]
    if len(pickles) != 1 or pickles[0].file_size > MAX_PICKLE_BYTES:
        raise ModelFileError(
            path, None, f"refused: not a torch.save archive with one pickle of at most "
            f"{MAX_PICKLE_BYTES:,} bytes",
        )  # fmt: skip
    f.seek(0)


def save_payload(path: str | os.PathLike, payload: dict) -> None:
    """Write ``payload`` (a dict with a ``"format"`` entry; tensors and plain values only)
    atomically to ``path``."""
    if "format" not in payload:
        raise UsageError("a payload must name its format")
    buf = io.BytesIO()
    torch.save(payload, buf)
    write_atomic(path, lambda f: f.write(buf.getvalue()))


def load_payload(
    path: str | os.PathLike, expected_format: str, max_bytes: int = MAX_CHECKPOINT_BYTES
) -> dict:
    """Load a file written by :func:`save_payload` with ``torch.load(weights_only=True)``.

    Args:
        path: the file.
        expected_format: the only accepted ``"format"`` entry, e.g. :data:`POLICY_FORMAT`.
        max_bytes: size limit of the file (a regular file only: :func:`sim.files.open_regular`).
    Returns:
        The payload dict (tensors on the CPU).
    Raises:
        FileNotFoundError: no file at ``path``.
        ModelFileError: anything else is wrong (one line naming the file and the problem).
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no file at {path}")
    try:
        with open_regular(path, max_bytes) as f, warnings.catch_warnings():
            check_archive(f, path)
            warnings.simplefilter("ignore")  # e.g. "Detected pickle protocol 4": verdict follows
            payload = torch.load(f, map_location="cpu", weights_only=True)
    except MotionDataError as e:  # not a regular file, too large: a refused model file
        raise ModelFileError(e.path, e.line, e.problem) from None
    except pickle.UnpicklingError as e:
        found = re.search(r"GLOBAL ([\w.]+)", str(e))
        if found:  # a pickled object of some class or function: exactly what must never load
            problem = f"holds objects other than tensors and plain values ({found.group(1)})"
        else:  # an opcode the safe unpickler does not accept, or not a pickle at all
            why = re.search(r"WeightsUnpickler error:\s*(.+)", str(e))
            problem = f"not a file of tensors and plain values ({why.group(1) if why else e})"
        raise ModelFileError(path, None, f"refused: {problem}"[:240]) from None
    except Exception as e:  # truncated, not a torch file, not a zip, ...
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ModelFileError(
            path, None, f"unreadable as a {expected_format} file: {first}"
        ) from None
    found = payload.get("format") if isinstance(payload, dict) else None
    if found != expected_format:
        raise ModelFileError(
            path, None, f"format {excerpt(repr(found))}; expected {expected_format!r}"
        )
    return payload
