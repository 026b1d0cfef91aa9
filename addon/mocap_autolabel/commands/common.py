"""What every command shares: the exit codes, the fill flags' values, the one-line error, bpy, reports."""

from __future__ import annotations

import json
import os
import sys

#: Exit codes: success, a file failed, bad usage.
EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
#: Seconds: the default --max-gap (core.fill.MAX_GAP).
DEFAULT_MAX_GAP = 1.0
#: The fill methods (core.fill.METHODS; written out here so that the parser loads no numpy).
FILL_METHODS = ("auto", "spline", "rigid", "hand", "pca", "pose")
#: The labeling methods and temporal modes, the first of each the default. The command line spells
#: the registries' names out (``--help`` imports no numpy); a test keeps them equal to the registries
#: (``core.labelers.LABELERS``, ``core.stages.decide.TEMPORAL_MODES``, ``core.fill.FILL_METHODS``).
LABEL_METHODS = ("set", "perm", "cnn", "gmm", "nearest")
TEMPORAL_MODES = ("vote", "viterbi", "none")


def _fail(path: str, exc: BaseException) -> int:
    from ..core.errors import MocapInputError

    if isinstance(exc, MocapInputError):
        print(f"error: {exc}", file=sys.stderr)
    elif isinstance(exc, OSError) and exc.strerror:  # a file that cannot be read or written: say which
        print(f"error: {exc.filename or path}: {exc.strerror}", file=sys.stderr)
    else:
        print(f"error: {path}: unexpected {type(exc).__name__}: {exc}", file=sys.stderr)
    return EXIT_FAILED


def _outputs_refused(file: str, outputs: list[str | None], inputs: list[str | None]) -> int | None:
    """:func:`..core.atomic.check_outputs` before a command's work (``inputs``: its files read, those
    that exist): the exit code after one line naming the output refused, or None where all can be
    written. A bad output found only at the end would leave the others written."""
    from ..core.atomic import check_outputs

    try:
        check_outputs(outputs, [p for p in inputs if p and os.path.isfile(p)])
    except OSError as exc:
        return _fail(file, exc)
    return None


def _bpy_or_none(what: str):
    """The bpy module, or None after telling the user how to get it."""
    try:
        import bpy
    except ImportError:
        print(f"error: {what} needs Blender: install the bpy module (pip install bpy==5.0.1) "
              "or run blender -b --python-exit-code 1 -P addon/mocap_autolabel/cli.py -- ...", file=sys.stderr)
        return None
    return bpy


def _write_report(path: str, report: dict) -> None:
    """``report`` as JSON at ``path``, whole or not at all (a folder or unwritable path raises OSError)."""
    from ..core.atomic import atomic_output

    if os.path.isdir(path):  # atomic_output refuses it too; this says which output wants a file name
        raise IsADirectoryError(21, "is a folder; give a file name for the report", path)
    with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1)
    print(f"  report   {path}")


def _allows_validation(temporal: str) -> bool:
    """Whether IK validation works with the temporal mode ``temporal`` (its registry's capability)."""
    from ..core.process import TEMPORAL_MODES as MODES

    return MODES[temporal].allows_validation
