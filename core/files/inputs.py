"""Opening the user's input files: only regular files, JSON decoded with one-line errors.

A named pipe, a device or a folder given where a file belongs is refused before it is opened
(opening a pipe blocks until someone writes to it, and Ctrl-C does not reach a blocked open).
Whatever the bytes hold, reading a JSON input ends in the decoded data or a
:class:`ZoopraxisError` naming the file: binary content, a cut-off file, nesting too deep for
the decoder. NaN and Infinity are decoded (results keep NaN in per-frame extras); the readers
check the numbers they use.
"""

import json
import stat
from pathlib import Path

from ..errors import ZoopraxisError

# No input of ours comes near this; a bigger one is a wrong file, not a take to decode.
MAX_JSON_BYTES = 1 << 30


def file_mode(path, what="file"):
    """``stat``'s mode of ``path`` (symlinks followed), without opening it.

    Raises
    ------
    ZoopraxisError
        Missing or not reachable, naming ``what``.
    """
    try:
        return Path(path).stat().st_mode
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such {what}") from None
    except OSError as error:
        raise ZoopraxisError(f"{path}: cannot read the {what} ({error.strerror})") from None


def check_regular_file(path, what="file"):
    """``path`` as a Path when it names an existing regular file (symlinks followed).

    Raises
    ------
    ZoopraxisError
        Missing, a folder, a pipe, socket or device, or not reachable; naming ``what``.
    """
    path = Path(path)
    mode = file_mode(path, what)
    if stat.S_ISDIR(mode):
        raise ZoopraxisError(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(mode):
        raise ZoopraxisError(f"{path}: is not a regular file (a pipe or a device?); "
                             f"give a {what}")
    return path


def read_json(path, what="file"):
    """Decode a JSON input file.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for messages ("markers file", "result file", ...).

    Returns
    -------
    data : object
        The decoded JSON.

    Raises
    ------
    ZoopraxisError
        For every way the file can fail to be readable JSON, naming the file (and the line
        when the decoder knows it).
    """
    path = check_regular_file(path, what)
    try:
        if path.stat().st_size > MAX_JSON_BYTES:
            raise ZoopraxisError(f"{path}: {path.stat().st_size} bytes is far too big for a "
                                 f"{what}")
        raw = path.read_bytes()
    except OSError as error:
        raise ZoopraxisError(f"{path}: cannot read the {what} ({error.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ZoopraxisError(f"{path}: not a text file (byte {error.start} is not UTF-8); "
                             f"expected a JSON {what}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise ZoopraxisError(f"{path}: not valid JSON ({error.msg} at line {error.lineno}, "
                             f"column {error.colno})") from None
    except ValueError as error:  # an integer of more digits than Python converts
        raise ZoopraxisError(f"{path}: not valid JSON ({error})") from None
    except RecursionError:
        raise ZoopraxisError(f"{path}: JSON nested too deep for a {what}") from None
