"""Old names of keyframe methods, still accepted: each warns and selects the method by its name
now (:func:`sidql.keyframes.methods.current_name`; on the command line
:func:`sidql.commands.usage.method_name`). Light to import: the command line reads it while it
parses, before any method is loaded."""

#: old name -> the method's name now.
RENAMED: dict[str, str] = {"xyz": "cartesian"}
