"""Writing the user's output files without ever costing them a file.

Every output is checked before any work (:func:`check_output`): not a folder, not one of the
command's inputs, in a folder that takes a new file. It is then written under a unique
temporary name beside the target (:func:`replacing`) and renamed over it only once complete,
so a failure - a full disk, a crash, Ctrl-C, a second run writing the same file - leaves the
old file byte for byte and no temporary file behind.
"""

import contextlib
import os
import tempfile
from pathlib import Path

from ..errors import ZoopraxisError


def _existing_folder(path):
    """The nearest folder above ``path`` that exists; ZoopraxisError if a file is in the way."""
    folder = path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise ZoopraxisError(f"{path}: {folder} is a file, not a folder")
    return folder


def _probe_writable(folder, path):
    # os.access says yes to root on a read-only mount; creating a file is the honest test.
    try:
        handle, probe = tempfile.mkstemp(prefix=".zoopraxis-probe.", dir=folder)
    except OSError as error:
        raise ZoopraxisError(f"{path}: cannot write into {folder} ({error.strerror})") from None
    os.close(handle)
    os.unlink(probe)


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(os.path.abspath(a)) == Path(os.path.abspath(b))


def check_output(path, force, *, inputs=(), suffixes=None, option="--out"):
    """Check an output before the work that fills it.

    Parameters
    ----------
    path : str or Path
    force : bool
        Whether an existing file may be replaced.
    inputs : iterable of (str, path or None)
        The command's inputs as ``(option, path)``; the output must be none of them.
    suffixes : tuple of str, optional
        Accepted file extensions, lower case with the dot.
    option : str
        How the output is named in messages.

    Returns
    -------
    path : Path

    Raises
    ------
    ZoopraxisError
        The output is a folder, one of the inputs, has the wrong extension, exists without
        ``force``, or its folder cannot take a new file.
    """
    path = Path(path)
    if str(path).endswith(os.sep) or path.is_dir():
        raise ZoopraxisError(f"{option} {path}: is a folder; give a file name")
    if suffixes and path.suffix.lower() not in suffixes:
        raise ZoopraxisError(f"{option} {path}: expected a {' or '.join(suffixes)} file name")
    for name, source in inputs:
        if source is not None and _same_file(path, source):
            raise ZoopraxisError(f"{option} {path}: is the same file as {name} {source}; "
                                 "write the output to another file")
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    if path.exists() and not path.is_file():
        raise ZoopraxisError(f"{option} {path}: is not a regular file")
    _probe_writable(_existing_folder(path), path)
    return path


@contextlib.contextmanager
def replacing(path, *, suffix=""):
    """Write ``path`` through a temporary file that replaces it only when complete.

    Yields the temporary path (an empty file in the target's folder, a unique name ending in
    ``.part`` and ``suffix``, e.g. the extension an exporter insists on); when the block ends
    without an exception the temporary file is renamed over ``path``, otherwise it is removed
    and ``path`` is left as it was. Missing folders above ``path`` are made.

    Raises
    ------
    ZoopraxisError
        An OSError while writing or renaming (a full disk, a read-only folder), naming
        ``path`` and saying the old file is untouched.
    """
    path = Path(path)
    existed = path.is_file()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part" + suffix,
                                             dir=path.parent)
        os.close(handle)
    except OSError as error:
        raise ZoopraxisError(f"{path}: cannot write ({error.strerror})") from None
    temporary = Path(temporary)
    try:
        yield temporary
        if not temporary.is_file() or temporary.stat().st_size == 0:
            raise ZoopraxisError(f"{path}: nothing was written"
                                 + ("; the old file is unchanged" if existed else ""))
        _set_mode(temporary, path)
        os.replace(temporary, path)
    except OSError as error:
        raise ZoopraxisError(f"{path}: cannot write ({error.strerror or error})"
                             + ("; the old file is unchanged" if existed else "")) from None
    finally:
        temporary.unlink(missing_ok=True)


def _set_mode(temporary, path):
    # mkstemp makes the file private; give it the old file's mode, or the umask's default.
    if path.is_file():
        mode = path.stat().st_mode & 0o7777
    else:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(temporary, mode)


def write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` through :func:`replacing`; returns the path."""
    with replacing(path) as temporary:
        with open(temporary, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
    return Path(path)
