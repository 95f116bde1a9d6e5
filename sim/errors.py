"""The project's one error hierarchy for bad input."""

from __future__ import annotations


class MotionDataError(ValueError):
    """Bad motion data: names the file, the line (when known) and the problem.

    Subclasses ``ValueError`` so generic callers can still catch it, but code in this project raises
    only this type for malformed input, never a bare IndexError/KeyError/ValueError from deep inside.
    """

    MAX_PROBLEM = 1000  # characters; a hostile token (a 100,000-character name) is cut short

    def __init__(self, path: str | None, line: int | None, problem: str):
        self.path = None if path is None else str(path)
        self.line = line
        if len(problem) > self.MAX_PROBLEM:  # cut to at most MAX_PROBLEM: pickling is stable
            problem = problem[: self.MAX_PROBLEM - 40] + f"... ({len(problem)} characters)"
        self.problem = problem
        where = self.path or "<input>"
        if line is not None:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        # Worker processes send errors back pickled; rebuild from the three fields.
        return (type(self), (self.path, self.line, self.problem))


class MotionDataWarning(UserWarning):
    """Input that was repaired rather than rejected (e.g. an incomplete final AMC frame dropped)."""
