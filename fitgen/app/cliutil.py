"""What every command-line tool here shares: one-line errors with exit status 2, the entry point, Ctrl-C."""

from __future__ import annotations

import argparse
import errno
import math
import os
import re
import signal
import sys

from fitgen.base.errors import InputError

EXIT_USAGE = 2
EXIT_PIPE = 128 + signal.SIGPIPE  # the reader went away: the status of a program SIGPIPE ends (cat, git)
EXIT_CHECK_FAILED = 1


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage dump) and exit status 2, and no abbreviated long options."""

    def __init__(self, *args, **kw):
        # no prefixes of long options: `fitgen simulate --n 20` was read as --noise 20 (volts), without a word
        kw.setdefault("allow_abbrev", False)
        super().__init__(*args, **kw)
        # argparse takes '-1e-3' for an option (its pattern knows no exponent): '--input-offset -1e-3' failed; and
        # a list led by a negative number too: '--temperature -10,25' failed where '--temperature=-10,25' worked
        number = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
        self._negative_number_matcher = re.compile(rf"^-{number}(\s*,\s*(-?{number})?)*$")

    def error(self, message):  # noqa: D401 - argparse's hook
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def finite(text: str) -> float:
    """An argparse type: a finite number."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return x


def count(text: str) -> int:
    """An argparse type: a whole number >= 0."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    return n


def noise_volts(text: str) -> float:
    """An argparse type: a noise figure in volts, a finite number >= 0 and at most MAX_NOISE (past every reading:
    a slip of the exponent, whose readings overflow)."""
    from fitgen.base.parse import MAX_NOISE

    x = finite(text)
    if not 0 <= x <= MAX_NOISE:
        raise argparse.ArgumentTypeError(f"must be >= 0 and at most {MAX_NOISE:g} V, got {x:g}")
    return x


def degc(text: str) -> float:
    """An argparse type: a temperature in the thermistor's range (host.temperature.T_RANGE), degC."""
    from host.temperature import T_RANGE

    x = finite(text)
    if not T_RANGE[0] <= x <= T_RANGE[1]:
        raise argparse.ArgumentTypeError(f"must be {T_RANGE[0]:g}..{T_RANGE[1]:g} degC (the thermistor's range), "
                                         f"got {x:g}")
    return x


def tcp_port(text: str) -> int:
    """An argparse type: a TCP port number, 1..65535 (leave the option out for a free one); one message for every
    number outside it, negative ones too."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if not 0 < n < 65536:
        raise argparse.ArgumentTypeError(f"{n} is not a TCP port number (1..65535; leave --port out for a free one)")
    return n


def seconds(text: str) -> float:
    """An argparse type: a time limit in seconds, > 0 and at most an hour."""
    from fitgen.base.parse import LONGEST_WAIT, parse_positive

    try:
        return parse_positive(text, "seconds", most=LONGEST_WAIT)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("seconds ")) from None


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a closed terminal or ssh session), raised where the program is, so that its temporary
    files and half-written outputs are cleaned up as for Ctrl-C (the default action ends the process with no
    cleanup at all)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__()
        self.signum = signum


def _terminate(signum, frame):
    raise Terminated(signum)


EXIT_INTERRUPTED = 130


def ended_by(stop: BaseException | None) -> tuple[str, int]:
    """What a command stopped by ``stop`` (a KeyboardInterrupt: Ctrl-C, or :class:`Terminated`) says and the status
    it exits with, as a shell gives a process a signal ended: 128 + the signal's number."""
    if isinstance(stop, Terminated):
        return ("hung up" if stop.signum == signal.SIGHUP else "terminated"), 128 + int(stop.signum)
    return "interrupted", EXIT_INTERRUPTED


ENDING = (signal.SIGTERM, signal.SIGHUP)  # the signals that end a command as Ctrl-C does, cleaned up


def catch_ending() -> dict:
    """Terminated raised for SIGTERM and SIGHUP from now on, except where the signal is ignored (nohup's SIG_IGN
    is kept: the command outlives its terminal as asked); the handlers replaced, to give back to
    :func:`restore`. Nothing outside the main thread (Python runs handlers only there)."""
    if not _main_thread():
        return {}
    return {s: signal.signal(s, _terminate) for s in ENDING if signal.getsignal(s) is not signal.SIG_IGN}


def ignore_ending() -> None:
    """Ctrl-C, SIGTERM and SIGHUP ignored from now on (in the main thread), for a process whose outcome is decided
    and which is shutting down: a Python handler would be reset at the interpreter's finalisation, the default
    action then ending it by the signal, with no line, its work done. SIGKILL still ends a shutdown that hangs."""
    if _main_thread():
        for s in (signal.SIGINT, *ENDING):
            signal.signal(s, signal.SIG_IGN)


def restore(previous: dict) -> None:
    for s, handler in previous.items():
        signal.signal(s, handler if handler is not None else signal.SIG_DFL)


class OutputFailed(Exception):
    """Standard output could not be written (a full disk, a closed terminal): not the program's fault."""


class _Stderr:
    """Standard error whose write failures (a full disk under 2>>log) are dropped: a diagnostic that cannot be
    said must not turn a command's status into a traceback's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except OSError:
            _drop(self._stream)
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except OSError:
            _drop(self._stream)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _tolerant(stream) -> None:
    """``stream`` to write a character its encoding lacks as an escape (a path's é to an ASCII terminal), not to
    raise UnicodeEncodeError."""
    try:
        stream.reconfigure(errors="backslashreplace")
    except (AttributeError, ValueError, OSError):  # not a TextIOWrapper (a test's capture): left as it is
        pass


class _Stdout:
    """Standard output whose write failures are told apart from any other OSError (which they look like)."""

    def __init__(self, stream):
        self._stream = stream

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise OutputFailed(exc.strerror or str(exc)) from None

    def write(self, text):
        return self._guard(self._stream.write, text)

    def flush(self):
        return self._guard(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def run(main_fn, argv=None, prog="") -> int:
    """Call ``main_fn(argv)``; turn bad input into one line on stderr and exit status 2. ``prog``: the name the
    line starts with, or a function giving it (the subcommand's, once parsed)."""
    previous = catch_ending()
    stdout, stderr = sys.stdout, sys.stderr
    # a stream closed before the start (>&-) is None in Python: its lines go nowhere, as the shell asked
    nowhere = [open(os.devnull, "w") for stream in (stdout, stderr) if stream is None]
    for stream in (stdout, stderr):
        if stream is not None:
            _tolerant(stream)
    sys.stderr = _Stderr(stderr if stderr is not None else nowhere[-1])
    sys.stdout = _Stdout(stdout if stdout is not None else nowhere[0])
    try:
        status = int(main_fn(argv) or 0)
        sys.stdout.flush()  # here, not at exit, so that a full disk is said as one line
        return status
    except InputError as exc:
        print(f"{_name(prog)}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as exc:
        said, status = ended_by(exc)
        print(f"{_name(prog)}: {said}", file=sys.stderr)
        return status
    except BrokenPipeError:  # the reader went away (| head): nothing more to say, and no verdict to give
        _drop(sys.stdout)
        return EXIT_PIPE
    except OutputFailed as exc:
        _drop(sys.stdout)
        print(f"{_name(prog)}: error: cannot write standard output: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # Path.is_file() and its kin raise this one where they return False for a missing file
        if exc.errno != errno.ENAMETOOLONG:
            raise
        from fitgen.base.fileio import too_long

        print(f"{_name(prog)}: error: {too_long(exc.filename or '')}", file=sys.stderr)
        return EXIT_USAGE
    except RecursionError:  # the JSON and TOML parsers recurse per bracket: no file fitgen writes nests so
        print(f"{_name(prog)}: error: an input file nests brackets too deeply to read: not a file fitgen or "
              "tactile-host wrote", file=sys.stderr)
        return EXIT_USAGE
    finally:
        sys.stdout, sys.stderr = stdout, stderr
        for stream in nowhere:
            stream.close()
        restore(previous)


def _name(prog) -> str:
    return prog() if callable(prog) else prog


def _drop(stream) -> None:
    """Point ``stream``'s file at the null device, so that Python's flush at exit has nothing to fail on."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (a test's capture): nothing to flush at exit
        pass


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def command_main(build_parser, argv, prog: str, check=None):
    """A command's entry point: parse ``argv`` with ``build_parser()``, let ``check(args)`` refuse option
    combinations, call the chosen subcommand's ``func(args)``; exit with its status (:func:`run`)."""

    name = [prog]  # the subcommand's once parsed, so that every line of it starts alike (as argparse's do)

    def main_fn(argv) -> int:
        parser = build_parser()
        if not (sys.argv[1:] if argv is None else argv):  # nothing asked: the commands there are, not one error
            parser.print_help(sys.stderr)
            return EXIT_USAGE
        args, extra = parser.parse_known_args(argv)
        name[0] = f"{prog} {args.command}"
        if extra:  # said by the subcommand's parser, so that the line starts with its name as its other errors do
            sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
            sub.choices[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
        if check is not None:
            check(args)
        return args.func(args)

    sys.exit(run(main_fn, argv, lambda: name[0]))


class StopFlag:
    """SIGINT, SIGTERM and SIGHUP (where not ignored) set a flag a loop checks between steps (the handlers are
    restored on exit)."""

    def __init__(self):
        self.stopped = False
        self.signum = signal.SIGINT  # the last that came

    def __call__(self) -> bool:
        return self.stopped

    def ended_by(self) -> tuple[str, int]:
        """What a command stopped by the signal says and its status, as :func:`ended_by` gives them."""
        return ended_by(Terminated(self.signum) if self.signum in ENDING else KeyboardInterrupt())

    def __enter__(self):
        def handler(signum, frame):
            self.stopped, self.signum = True, signum

        self._old = {s: signal.signal(s, handler) for s in (signal.SIGINT, *ENDING)
                     if s == signal.SIGINT or signal.getsignal(s) is not signal.SIG_IGN}
        return self

    def __exit__(self, *exc):
        restore(self._old)


WRITES = ("output", "record", "temp_comp_output", "pose_file", "junit")  # the files a command writes
READS = ("model", "run", "tempcomp", "adc", "temp_comp", "rest", "poses", "data", "replay", "sensor", "sim_sensor",
         "capture", "captures", "samples")  # and those it reads: never one of the written


STDOUT_DEFAULT = ("cmd_read", "cmd_report")  # commands whose -o, left out, is stdout: there "-o -" says so too


def check_written(args, files=()) -> None:
    """Every file a command writes, checked before the work: no folder, none of its inputs, no two alike.
    ``files``: the commands whose ``-o`` is a file (for the others it is a folder)."""
    import os
    from pathlib import Path

    from fitgen.base.fileio import check_folder, output_file, refuse_inputs
    from fitgen.physics.dataset import meta_path

    def is_file(p) -> bool:  # an option that names a file or a count (--samples): a long count is no file
        try:
            return Path(p).is_file()
        except OSError:
            return False

    given = [getattr(args, n, None) for n in READS]
    given = [p for g in given for p in (g if isinstance(g, list) else [g])]  # a list: files of one option
    inputs = [p for p in given if isinstance(p, str) and is_file(p)]
    inputs += [str(m) for m in map(meta_path, inputs) if m.is_file()]  # a dataset's meta is read with it
    written = []  # (flag, path) of the outputs checked so far

    def written_as(path):  # the output already named that file (realpath: a symlink is written through), or None
        return next(((f, o) for f, o in written if os.path.realpath(o) == os.path.realpath(path)), None)

    for name in WRITES:
        path = getattr(args, name, None)
        if not isinstance(path, str):
            continue
        flag = "-o" if name == "output" else f"--{name.replace('_', '-')}"
        if path == "-":
            if name == "output" and getattr(args.func, "__name__", "") in STDOUT_DEFAULT:
                args.output = None  # the command's own stdout
                continue
            raise InputError(f"{flag} -: give a {'folder' if name == 'output' and args.func not in files else 'file'}"
                             " name (this command writes nothing to stdout)")
        if name == "output" and args.func not in files:  # a folder the command makes
            check_folder(path)
            continue
        output_file(path, inputs, flag)
        if same := written_as(path):
            raise InputError(f"{same[0]} and {flag} name the same file {path}: give two")
        written.append((flag, path))
    plot = getattr(args, "plot", None)
    for name in PLOT_FILES.get(getattr(args, "command", None), ()) if isinstance(plot, str) else ():
        if same := written_as(os.path.join(plot, name)):
            raise InputError(f"{same[0]} {same[1]} is the plot --plot {plot} writes: give another name")
        for path in Path(plot).glob(name):  # report's names: estimate_dx.png, ... (a dataset once had one)
            refuse_inputs(path, inputs, "--plot writes", "give --plot another folder")


# the plots a command's --plot FOLDER holds, by name or pattern
PLOT_FILES = {"noise": ("allan.png",), "identify": ("identify.png",), "check": ("check.png",),
              "report": ("estimate_*.png", "sweep_*.png")}

STYLE_WITH_FIXED = "--style does not apply to --precision fixed (its header is straight-line code)"

def check_not_empty(args) -> None:
    """An option given as an empty string is refused (it would otherwise fall back to its default unsaid)."""
    for name, value in vars(args).items():
        if isinstance(value, str) and not value.strip():
            flag = ("-o" if name == "output" else name.removesuffix("_pos") if name.endswith("_pos")
                    else "--" + name.replace("_", "-"))
            raise InputError(f"{flag} is empty")
