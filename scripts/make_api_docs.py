"""Build the API reference of ``sim`` and ``sidql`` from their docstrings (pdoc, extra ``test``).

    python scripts/make_api_docs.py [OUT]     # default OUT: docs/api (not committed)

Every module of both packages gets a page (the packages' ``__all__`` lists their flat API only,
so the modules are named explicitly); OUT/index.html is the entry. ``tests/test_api_docs.py``
builds it into a temporary folder and checks that the key public names are documented.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sim", "sidql")


def module_names() -> list[str]:
    """Every module of :data:`PACKAGES` by its dotted name, from the files (a folder without
    ``__init__.py``, a namespace package, is walked too), sorted."""
    names = set()
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            if "__pycache__" not in path.parts:
                dotted = ".".join(path.relative_to(ROOT).with_suffix("").parts)
                names.add(dotted.removesuffix(".__init__"))
    return sorted(names)


def build(out_dir: str | os.PathLike) -> Path:
    """Write the HTML reference into ``out_dir``; returns its index.html."""
    os.environ.setdefault("MUJOCO_GL", "egl")  # modules that render import MuJoCo's GL backend
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import importlib

    import pdoc  # the test extra; imported here so that module_names() needs no pdoc

    for package in PACKAGES:  # the flat API loads lazily (PEP 562): pdoc reads module __dict__s
        module = importlib.import_module(package)
        for name in module.__all__:
            setattr(module, name, getattr(module, name))
    out = Path(out_dir)
    # Each module is named once here; pdoc also reaches some through their package, and says so.
    warnings.filterwarnings("ignore", message="The module specification .* already been added")
    pdoc.render.configure(docformat="google", show_source=False, search=True)
    pdoc.pdoc(*module_names(), output_directory=out)
    return out / "index.html"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    index = build(argv[0] if argv else ROOT / "docs" / "api")
    print(f"wrote {index}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
