"""Atomic file writes and checked reads: nothing half-written, every output checked before the work."""

from __future__ import annotations

import errno
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from fitgen.base.errors import InputError
from fitgen.base.signals import signals_held


NAME_MAX = 255  # bytes in one name on Linux's file systems (ext4, xfs, btrfs, tmpfs)
# the most of an output's name a temporary's prefix keeps: "." + name + "." + mkstemp's 8 letters + ".partial"
_TEMP_NAME_MAX = NAME_MAX - 1 - 1 - 8 - len(".partial")


def temp_prefix(name: str) -> str:
    """A prefix for a temporary beside the output ``name``: ``.name.``, the name cut so that the temporary's own
    name stays within NAME_MAX (a legal name of 242-255 bytes had been refused as too long)."""
    while len(os.fsencode(name)) > _TEMP_NAME_MAX:
        name = name[:-1]
    return f".{name}."


def _new_mode(target: Path) -> int:
    """The mode a replaced file keeps, or a new file's under the umask (mkstemp's 0600 would hide it)."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode) & 0o777  # no set-id bit onto new contents
    except OSError:
        return 0o666 & ~_UMASK


def _read_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()  # once, at import: os.umask can only be read by setting it, which threads would race


def folder_of(path: str | os.PathLike) -> Path:
    """The folder ``path`` is to be written in; one line (InputError) when it does not exist, which a command
    checks before its work, not after it."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"cannot write {path}: {folder} is a file, not a folder" if folder.exists()
                         else f"cannot write {path}: folder {folder} does not exist")
    return folder


_NOT_FILES = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
              (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"))


def _kind(mode) -> str:
    if stat.S_ISREG(mode):
        return "a file"
    return next((name for test, name in _NOT_FILES if test(mode)), "of no kind known")


def _not_a_file(path, mode) -> InputError:
    kind = _kind(mode)
    what = f"a symlink to {os.readlink(path)}, {kind}" if os.path.islink(path) else kind
    return InputError(f"cannot write {path}: it is {what}, not a file; give a file's path")


def write_target(path: str | os.PathLike) -> Path:
    """The file that writing ``path`` replaces: ``path``, or the file its symlinks lead to (written through, the
    links kept); InputError when that exists and is not a regular file (a device, FIFO, socket or folder)."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode  # through every link, /proc/self/fd's too
    except (FileNotFoundError, NotADirectoryError):
        mode = None  # a new file, or a folder that is not one: folder_of says which
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    if mode is not None and not stat.S_ISREG(mode):
        raise _not_a_file(path, mode)
    if os.path.islink(path) and _through_descriptor(path):
        # /dev/stdout redirected to a file: replacing that file would destroy what the shell appends to (>>)
        raise InputError(f"cannot write {path}: it leads to an open file descriptor (as /dev/stdout does), not a "
                         "file; give a file's path")
    return real_file(path)


def _through_descriptor(path: Path) -> bool:
    """True when ``path`` or a link on its chain of symlinks is a descriptor's link: an entry of /proc/<pid>/fd
    (/dev/fd and /proc/self/fd lead there)."""
    hop = str(path)
    for _ in range(40):  # the kernel's own limit on links followed
        if not os.path.islink(hop):
            return False
        parts = Path(os.path.realpath(os.path.dirname(os.path.abspath(hop)))).parts
        if parts[:2] == ("/", "proc") and parts[-1] == "fd":
            return True
        hop = os.path.normpath(os.path.join(os.path.dirname(hop), os.readlink(hop)))
    return False


def real_file(path: str | os.PathLike) -> Path:
    """``path``, or the file its symlinks lead to: where the files written beside it (a meta, a posterior, a
    lock) belong, so that they are found by either name."""
    path = Path(path)
    return Path(os.path.realpath(path)) if os.path.islink(path) else path


def output_file(path: str | os.PathLike, inputs=(), flag: str = "-o") -> Path:
    """``path`` checked as a file to write before the work: a name, not a folder, device or FIFO, in a folder that
    exists and takes a new file, and none of the command's ``inputs`` (which it would overwrite); InputError
    otherwise."""
    given_name, path = os.fspath(path), Path(path)
    # Path drops a trailing slash, which asks for a folder: "-o new/" had written a file named "new"
    if path.name in ("", ".", "..") or path.is_dir():
        raise InputError(f"cannot write {path}: it is a folder; give a file name")
    if given_name.endswith(os.sep):
        raise InputError(f"cannot write {given_name}: a name ending in {os.sep} is a folder's; give a file name")
    target = write_target(path)
    # a file made and removed as write_atomic will make it: permissions do not tell (root passes os.access, and
    # /proc refuses new files to root too), and an output written last would fail after all the work
    try:
        fd, tmp = tempfile.mkstemp(dir=folder_of(target), prefix=temp_prefix(target.name), suffix=".tmp")
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(tmp)
    refuse_inputs(path, inputs, flag)
    return path


def refuse_inputs(path: Path, inputs, said: str, fix: str = "give another name") -> None:
    """InputError where ``path`` is one of ``inputs``, by any name (a link, the folder named another way)."""
    for given in inputs:
        # Path(given): "data.csv/" names the file as the loaders read it; samefile on the string raised ENOTDIR
        if given is not None and path.exists() and Path(given).exists() and os.path.samefile(Path(given), path):
            raise InputError(f"{said} {path} is the input {given}: writing it would destroy it; {fix}")


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` (through a symlink, to the file it leads to) by a temporary file in the same
    folder and a rename; InputError, nothing written, when ``path`` is not a regular file (:func:`write_target`)."""
    path = Path(path)
    target = write_target(path)
    folder_of(target)
    tmp = _staged(target, data, path)
    try:
        os.replace(tmp, target)
    except OSError as exc:
        _remove(tmp)
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    except BaseException:  # Ctrl-C between the two: no temporary left
        _remove(tmp)
        raise
    return path


def replaces_other(path: str | os.PathLike, text: str) -> bool:
    """Whether writing ``text`` to ``path`` replaces a file that says something else (a unit a model is tied to)."""
    try:
        return Path(path).read_text() != text
    except (OSError, UnicodeDecodeError):  # none there (or not a text file: the write says what it says)
        return False


def write_all(files) -> list:
    """Write every ``(path, data)`` of ``files``, or none of them: each is first written whole under a temporary
    name beside the file it replaces (through a symlink, as :func:`write_atomic`; its folder made when missing),
    and renamed into place only when all are. A failure removes the temporaries and the folders made for them:
    InputError, one line. Returns the paths."""
    files = [(Path(path), data) for path, data in files]
    seen = {}
    for path, _ in files:  # two of them one file: the later would replace the earlier unsaid
        if (real := os.path.realpath(path)) in seen:
            raise InputError(f"{seen[real]} and {path} name the same file: give two")
        seen[real] = path
    staged, made = [], []  # (temporary, the file it replaces, the path given); the folders this call made
    try:
        for path, data in files:
            target = write_target(path)  # a folder, device or FIFO is refused
            made += [f for f in (target.parent, *target.parent.parents) if not f.exists()]
            make_folder(target.parent)
            staged.append((_staged(target, data, path), target, path))
        with signals_held():  # a Ctrl-C between two renames would leave new files beside old ones
            while staged:  # each folder took a new file and no target is a folder: a rename fails only in a race
                tmp, target, path = staged[0]
                try:
                    os.replace(tmp, target)
                except OSError as exc:
                    done = [str(p) for p, _ in files[:len(files) - len(staged)]]
                    raise InputError(f"cannot write {path}: {exc.strerror}"
                                     + (f" ({', '.join(done)} written)" if done else "")) from None
                staged.pop(0)
    except BaseException:  # an InputError, or Ctrl-C: nothing half-written either way
        for tmp, _, _ in staged:
            _remove(tmp)
        for folder in sorted(set(made), key=lambda f: len(f.absolute().parts), reverse=True):
            try:
                folder.rmdir()  # only when empty: a folder made here holds nothing else
            except OSError:
                pass
        raise
    return [path for path, _ in files]


def _staged(target: Path, data: str | bytes, path) -> str:
    """``data`` written whole and synced to a new temporary file beside ``target``; its name. InputError naming
    ``path`` (the name the user gave), nothing left, when it cannot be."""
    try:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=temp_prefix(target.name), suffix=".tmp")
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_mode(target))
    except BaseException as exc:  # Ctrl-C too: the temporary goes
        _remove(tmp)
        if isinstance(exc, OSError):
            raise InputError(f"cannot write {path}: {exc.strerror}") from None
        raise
    return tmp


def _remove(tmp: str) -> None:
    try:
        os.unlink(tmp)
    except OSError:
        pass


def open_output(path: str | os.PathLike, append: bool = False) -> int:
    """A descriptor writing ``path`` in place, for a file written as the work goes (rows, a run record): created
    or emptied, or with ``append`` an existing file added to; InputError when ``path`` is not a regular file."""
    folder_of(write_target(path))
    # O_NONBLOCK: a FIFO made since the check neither blocks the open nor is written; no O_TRUNC before fstat
    # says it is a file
    flags = os.O_WRONLY | os.O_NONBLOCK | (os.O_APPEND if append else os.O_CREAT)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        raise InputError(f"cannot {'append to' if append else 'write'} {path}: {exc.strerror}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise _not_a_file(path, mode)
        if not append:
            os.ftruncate(fd, 0)
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


class OutputText:
    """A text file written as the work goes (:func:`open_output`'s): a write that fails there (a full disk, a file
    size limit) is InputError naming the file, one line, not a traceback after minutes of work."""

    def __init__(self, path: str | os.PathLike, append: bool = False):
        self.path = path
        self._fh = os.fdopen(open_output(path, append), "w")

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except OSError as exc:
            raise InputError(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def write(self, text: str) -> int:
        return self._guard(self._fh.write, text)

    def flush(self) -> None:
        self._guard(self._fh.flush)

    def close(self, quiet: bool = False) -> None:
        """Closed; what could not be flushed is said (InputError) once, unless ``quiet`` (another error or a signal
        is ending the work, and is the one to say), and the descriptor is closed either way."""
        if not self._fh.closed:
            try:
                self._guard(self._fh.flush)
            except InputError:
                if not quiet:
                    raise
            finally:
                try:
                    self._fh.close()
                except OSError:  # the flush above said it
                    pass


def make_folder(folder: str | os.PathLike) -> Path:
    """``folder``, created (and its parents) when missing; one line (InputError) when it cannot be."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError("cannot create {}: {} is {}; give a folder".format(folder, *_in_the_way(folder))) from None
    except OSError as exc:
        raise InputError(f"cannot create {folder}: {exc.strerror}") from None
    return folder


def _in_the_way(folder: Path) -> tuple[Path, str]:
    """What stands where ``folder``, or a folder on the way to it, goes: its path, and its kind ('a file')."""
    where = next(p for p in [folder, *folder.parents] if p.exists() and not p.is_dir())
    return where, _kind(where.stat().st_mode)


def check_folder(folder: str | os.PathLike, flag: str = "-o") -> Path:
    """``folder`` checked as one a command will make and write into, without making it (so that a command refused
    later leaves none behind): a name, not a file, under a folder that takes a new folder; InputError otherwise."""
    path = Path(folder)
    if not str(folder).strip():
        raise InputError(f"{flag} is empty: give a folder")
    if path.exists() and not path.is_dir():
        raise InputError(f"{flag} {path}: it is {_kind(path.stat().st_mode)}; give a folder")
    try:
        base = path.absolute()
    except OSError as exc:  # a working folder removed since the shell entered it: a relative name leads nowhere
        raise InputError(f"cannot create {path}: the working folder is gone ({exc.strerror}); cd to one that "
                         "exists, or give an absolute path") from None
    while not os.path.lexists(base):  # lexists: a dangling symlink on the way is no folder to make
        base = base.parent
    if not base.is_dir():
        raise InputError(f"cannot create {path}: {base} is not a folder")
    # a folder (or, in one that exists, a file) made and removed: permissions do not tell (root passes os.access,
    # and /proc refuses new folders to root too)
    try:
        if base == path.absolute():
            fd, probe = tempfile.mkstemp(dir=base, prefix=".probe.", suffix=".tmp")
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(dir=base, prefix=".probe.", suffix=".tmp"))
    except OSError as exc:
        raise InputError(f"cannot write in {path}: {exc.strerror}" if base == path.absolute()
                         else f"cannot create {path}: {base} takes no new folder ({exc.strerror})") from None
    return path


def foreign_files(where: str, held: list, writer: str, writes: str,
                  fix: str = "give a new or empty folder") -> InputError:
    """The refusal of a folder ``where`` that holds files (``held``) which no ``writer`` wrote and over which a run
    would write: ``writes`` says what, before "over files of those names"."""
    listed = ", ".join(held[:3]) + (", ..." if len(held) > 3 else "")
    return InputError(f"{where} holds files no {writer} wrote ({listed}), and {writes} over files of those names: "
                      f"{fix}")


def write_in_folder(folder: str | os.PathLike, name: str, data: str | bytes, inputs=(),
                    ours: tuple[bytes, str] | None = None) -> Path:
    """:func:`write_atomic` into ``folder/name``, creating ``folder`` (and its parents) when missing; a write that
    fails leaves no folder it made (:func:`write_all`). InputError where that is one of the command's ``inputs``
    (a model file named tm_model.h, in the folder codegen writes its header to), or, with ``ours`` (what a file
    the writer wrote holds in its first kilobyte, and the writer's name), a file there which does not hold it."""
    path = Path(folder) / name
    refuse_inputs(path, inputs, "the file written", "give another folder")
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None  # nothing there (write_atomic says what else is wrong)
    if mode is not None and not stat.S_ISREG(mode):  # the user named the folder: the name inside is ours
        raise InputError(f"cannot write {path}: {_kind(mode)} of that name is in the way; move it or give "
                         "another folder")
    if mode is not None and ours is not None and ours[0] not in _head(path):  # a header of the user's own
        raise InputError(f"cannot write {path}: a file of that name is there which no {ours[1]} wrote; move it or give "
                         "another folder")
    return write_all([(path, data)])[0]


def _head(path: Path) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(1024)
    except OSError:  # unreadable: write_atomic says whether it can be replaced
        return b""


def too_long(name) -> str:
    """What is said of a file name longer than the system takes, the name cut short."""
    return f"a file name is too long for this system ({str(name)[:40]}...)"


def _device(path) -> str | None:
    """What ``path`` is when it is a device other than a terminal (which ends where its user types the end)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None  # said as read_bytes says it
    if not (stat.S_ISCHR(mode) or stat.S_ISBLK(mode)):
        return None
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:
        return None
    try:
        return None if os.isatty(fd) else _kind(mode)
    finally:
        os.close(fd)


def read_text(path: str | os.PathLike, what: str) -> str:
    """A text file's content; a missing or unreadable file, or one that is not UTF-8 text, is an InputError naming
    ``what`` (and the line of the first byte that is not UTF-8)."""
    device = _device(path)
    if device:  # /dev/zero, a disk: read to their end, they fill the memory first
        raise InputError(f"{what} {path}: {device}, not a file")
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} {path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{what} {path}: a folder, not a file") from None
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:  # as the commands' own handler says it, the name cut short
            raise InputError(f"{what}: {too_long(path)}") from None
        raise InputError(f"{what} {path}: cannot read: {exc}") from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise InputError(f"{what} {path}: UTF-16 text (a spreadsheet's 'Unicode text'): save it as UTF-8 (in a "
                         "spreadsheet, 'CSV UTF-8')")
    data = data.removeprefix(b"\xef\xbb\xbf")  # the byte-order mark spreadsheets write (off first: the line below)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"{what} {path}: line {line} is not UTF-8 text (byte 0x{data[exc.start]:02x}, from another "
                         "encoding such as Latin-1): save it as UTF-8") from None
    # as read_text with universal newlines: CRLF and CR line ends read as LF
    return text.replace("\r\n", "\n").replace("\r", "\n")


@contextmanager
def staged_beside(folder: Path):
    """A new hidden folder beside ``folder`` (on its file system, so that what is built in it renames into
    ``folder`` whole), removed on exit with whatever is left in it; InputError naming ``folder`` when it cannot
    be made."""
    try:
        partial = Path(tempfile.mkdtemp(prefix=temp_prefix(folder.name), suffix=".partial", dir=folder.parent))
    except OSError as exc:  # e.g. under /proc, which a root user may "write"
        raise InputError(f"cannot write {folder}: {exc.strerror}") from None
    try:
        yield partial
    except InputError as exc:  # a compiler's line names the staged copy, which goes: the generated file's name
        if str(partial) not in str(exc):
            raise
        raise InputError(str(exc).replace(str(partial) + os.sep, "").replace(str(partial), str(folder))) from None
    finally:
        shutil.rmtree(partial, ignore_errors=True)


class _HeldFolder:
    """A descriptor of a folder holding its flock; ``close()`` releases it."""

    def __init__(self, fd: int):
        self.fd = fd

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def hold_folder(folder: Path, who: str, option: str) -> _HeldFolder:
    """An exclusive lock on ``folder`` (created), held until the returned object is closed or the process ends:
    an flock on the folder itself, so that no lock file is left in it; InputError when another process holds
    it, naming ``who`` holds such folders and the ``option`` that gives each its own."""
    import fcntl

    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except (FileExistsError, NotADirectoryError):
        where, kind = _in_the_way(folder)
        raise InputError(f"{option} {folder}: {'it' if where == folder else where} is {kind}; give a folder") from None
    except OSError as exc:
        raise InputError(f"{option} {folder}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputError(f"{option} {folder} is in use by another {who} (a build, or a firmware running from it): "
                         f"give each its own {option}") from None
    return _HeldFolder(fd)
