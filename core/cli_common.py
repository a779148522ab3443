"""Argument helpers shared by the commands."""

from .errors import ZoopraxisError


def parse_view_values(items, what, convert=str):
    """``["cam0=PATH", ...]`` -> ordered dict of view name to value.

    Raises
    ------
    ZoopraxisError
        An item without ``=``, an empty name or value, a view named twice, or a value that
        ``convert`` refuses, in one line naming the option.
    """
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise ZoopraxisError(f"{what} must look like VIEW=VALUE (e.g. cam0=plates/cam0), "
                                 f"got '{item}'")
        if name in out:
            raise ZoopraxisError(f"{what}: view '{name}' is given twice")
        try:
            out[name] = convert(value)
        except ValueError:
            raise ZoopraxisError(f"{what} {item}: '{value}' is not valid") from None
    return out


def parse_flips(items):
    """``--flip FRAME:PART`` options as ``{frame: [part, ...]}`` (None when there are none).

    Raises
    ------
    ZoopraxisError
        An option that is not FRAME:PART with a known part.
    """
    from .initialize import parse_flip

    out = {}
    for item in items or ():
        frame, part = parse_flip(item)
        if part not in out.setdefault(frame, []):
            out[frame].append(part)
    return out or None


def add_output_arguments(parser, what):
    """``--out`` (the file to write, described by ``what``) and ``--force``."""
    parser.add_argument("--out", required=True, help=f"{what} to write")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")


def check_output(path, force):
    """The output path as a Path; refuses to replace an existing file without --force."""
    from pathlib import Path

    path = Path(path)
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    return path


def open_plates(paths, fps=None):
    """Open ``{view: path}`` plates; returns ``{view: Plate}`` (one-line errors per path)."""
    from .plates import open_plate

    if not paths:
        raise ZoopraxisError("give at least one --plate VIEW=PATH")
    return {name: open_plate(path, name=name, fps=fps) for name, path in paths.items()}
