"""The ``simfab`` command: one subcommand per module in this package.

Each subcommand module defines ``HELP`` (one line), ``add_args(parser)`` and
``run(args) -> dict``. The dict is the run's summary: output paths and key figures; with
``--json`` it is printed as exactly one JSON object on stdout, otherwise as compact tables
(:mod:`simfab.cli._summary`; units from the summary's ``units``, the module's ``UNITS`` and
key suffixes). A module may also define ``demo(ctx: DemoContext) -> dict`` to take part in
``simfab demo``, and ``output_roots(args) -> list`` (the folders it writes into; default
``[args.out]``, empty for commands that write nothing).

Before a subcommand runs, every output folder is checked (an existing file, an unwritable folder:
exit 2 before any computation), and every file written through :mod:`simfab.io.atomic` must lie
inside one of them (:mod:`simfab.io.outpaths`). Outputs are all or nothing: when a run fails (or
is interrupted: Ctrl-C, SIGTERM) every file it wrote is removed, every file it replaced restored
and the folders it created removed (``sweep`` keeps what it finished: it resumes from it; a
validation that ran and missed its tolerance keeps its report, exit 1).

Exit codes: 0 ok; 2 bad input (one line on stderr naming the file/field, no traceback); 1 internal
failure or a solver that did not converge (one line, traceback only with ``SIMFAB_DEBUG=1``).
Warnings raised while a subcommand runs (simfab's own, NumPy's invalid value, divide by zero) are
shown after a successful run and dropped on the error path, so an error stays one line on stderr.

Subcommand modules import the library inside their functions, deliberately: ``simfab --help``,
a subcommand's ``--help`` and argument errors answer without loading Warp, MuJoCo, OpenUSD and
the solvers (seconds of start-up).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import importlib
import json
import os
import re
import signal
import sys
import threading

from simfab.errors import ConvergenceError, InputError, ValidationFailed
from simfab.io.outpaths import check_out_dir, confine, published_on_success, require_nonempty

#: Subcommands in the order ``simfab --help`` lists them.
SUBCOMMANDS = ("grow", "couple", "deploy", "crowd", "sweep", "validate", "demo", "render", "inspect")

_MODULE = {"inspect": "inspect_"}  # avoid shadowing the stdlib ``inspect`` module


def subcommand_module(name: str):
    """Import the module implementing subcommand ``name``."""
    return importlib.import_module(f"simfab.cli.{_MODULE.get(name, name)}")


def add_common_args(p: argparse.ArgumentParser) -> None:
    """Flags every subcommand takes (also after the subcommand name)."""
    g = p.add_argument_group("common options")
    g.add_argument("--out", default=argparse.SUPPRESS, metavar="DIR",
                   help="output folder (default ./simfab-out/<subcommand>)")
    g.add_argument("--seed", type=_seed, default=argparse.SUPPRESS, metavar="N",
                   help="random seed, an integer 0 <= N < 2**32 (default 0)")
    g.add_argument("--device", choices=["cpu", "cuda"], default=argparse.SUPPRESS, help="Warp device (default cpu)")
    g.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="no progress bars and no log lines; still prints the short result table and the output "
                        "paths (warnings and errors still go to stderr)")
    g.add_argument("--json", action="store_true", default=argparse.SUPPRESS,
                   help="for scripts: print exactly one JSON object (output paths and key figures) on stdout, "
                        "nothing else; implies --quiet")


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if not 0 <= v < 2**32:
        raise argparse.ArgumentTypeError(f"must be in 0 .. 2**32 - 1, got {v}")
    return v


class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions render as written: hand-laid lists, examples and line breaks are kept when the
    terminal is wide enough; on a narrower one each paragraph (or list item with its hanging
    continuation lines) is refilled as a whole, so no sentence breaks in the middle."""

    def _fill_text(self, text, width, indent):
        out = []
        for item in help_items(text.splitlines()):
            if not item[0].strip():
                out.append("")
            elif all(len(indent) + len(line) <= width for line in item):
                out += [indent + line for line in item]  # as written
            else:
                out += _refill(item, width, indent)
        return "\n".join(out)


def _lead(line: str) -> int:
    return len(line) - len(line.lstrip())


def help_items(lines: list[str]) -> list[list[str]]:
    """A description's lines grouped into items: a blank line; an unindented paragraph (its lines
    up to a blank or an indented line); an indented line with the lines below indented deeper (a
    list entry and its hanging continuation). Indented lines after a line ending in ':' are a list.

    Args:
        lines: the description's lines as written.

    Returns:
        The items, each a list of its lines; the help formatter refills each item on its own.
    """
    items: list[list[str]] = []
    for line in lines:
        prev = items[-1] if items else None
        if prev and line.strip() and prev[0].strip() and (
                (_lead(prev[0]) == 0 and _lead(line) == 0)
                or (_lead(line) > _lead(prev[0]) and not prev[-1].rstrip().endswith(":"))):
            prev.append(line)
        else:
            items.append([line])
    return items


def _refill(item: list[str], width: int, indent: str) -> list[str]:
    """One item refilled to ``width``: its first line's indentation first, its continuation lines'
    (or two more spaces) after."""
    import textwrap

    lead = item[0][: _lead(item[0])]
    column = re.match(r"\s+\S+(?: \S+)*\s{2,}", item[0])  # an indented entry's text column: "  name    text"
    if len(item) > 1:
        hang = item[1][: _lead(item[1])]
    elif column and len(column.group(0)) <= width // 2:
        hang = " " * len(column.group(0))
    else:
        hang = lead + ("  " if lead else "")
    text = ""
    for line in (x.strip() for x in item):  # a word hyphenated across lines ("mesh-" "converged") stays one
        text += line if not text or re.search(r"[A-Za-z]-$", text) else " " + line
    return textwrap.wrap(text, max(width, 20), break_on_hyphens=False,
                         break_long_words=False, initial_indent=indent + lead, subsequent_indent=indent + hang)


class _Parser(argparse.ArgumentParser):
    """argparse that raises InputError instead of exiting, so main() owns the exit code."""

    def __init__(self, *a, **kw):
        kw["formatter_class"] = _Formatter
        super().__init__(*a, **kw)

    def error(self, message):  # noqa: D401 - argparse API
        raise InputError(f"{self.prog}: {message}")


#: Common options that take a value (skipped when looking for the subcommand's name in argv).
_VALUED = ("--out", "--seed", "--device")


def invoked_subcommand(argv: list[str]) -> str | None:
    """The subcommand named in ``argv`` (the first word that is not a common option or its value), or
    None when there is none, it is not a known subcommand, or a help/version flag comes first (the
    top-level help lists every subcommand)."""
    skip = False
    for tok in argv:
        if skip:
            skip = False
        elif tok in ("-h", "--help", "--version"):
            return None
        elif tok in _VALUED:
            skip = True
        elif not tok.startswith("-"):
            return tok if tok in SUBCOMMANDS else None
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The CLI's parser; ``only``: build (and import) that subcommand's module alone - the one argv
    invokes - so a command does not pay the imports of the others (the crowd CLI's FEM kernels, say)."""
    from simfab import __version__

    parser = _Parser(prog="simfab", description="Computational fabrication design built around physics simulation.")
    parser.add_argument("--version", action="version", version=f"simfab {__version__}")
    add_common_args(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in SUBCOMMANDS if only is None else (only,):
        mod = subcommand_module(name)
        sp = sub.add_parser(name, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        add_common_args(sp)
        mod.add_args(sp)
        sp.set_defaults(_module=mod)
    return parser


DEFAULTS = {"out": None, "seed": 0, "device": "cpu", "quiet": False, "json": False}


def main(argv: list[str] | None = None) -> int:
    """Run the CLI in-process; return the exit code (never calls ``sys.exit``)."""
    import warnings

    warnings.showwarning = _show_warning
    _HELD.clear()
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        parser = build_parser(invoked_subcommand(argv))
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help / --version
            return int(e.code or 0)
        for k, v in DEFAULTS.items():
            if not hasattr(args, k):
                setattr(args, k, v)
        if args.command is None:
            parser.print_help(sys.stderr)
            return 2
        if args.out is not None:  # --out "$UNSET": refused by every subcommand, also those that write elsewhere
            require_nonempty(args.out, "--out")
        if args.out is None:  # a module may name its own default folder (demo: ./simfab-out)
            args.out = getattr(args._module, "DEFAULT_OUT", os.path.join("simfab-out", args.command))
        if args.json:
            args.quiet = True
        roots = _output_roots(args)
        for r in roots:  # before any computation: a bad --out is bad input (exit 2), not a late crash
            check_out_dir(r, where=_OUT_FLAG.get(args.command, "--out"))
        interrupts = _Interrupts()
        with confine(roots), interrupts, _all_or_nothing(args.command, roots), interrupts.run(), _HoldWarningLines():
            result = args._module.run(args)
        _flush_held_warnings()
        _report(result, args)
        return 0
    except InputError as e:
        _drop_held_warnings()
        print(f"simfab: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except ValidationFailed as e:
        _drop_held_warnings()
        print(f"simfab: validation failed: {_one_line(e)}", file=sys.stderr)
        return 1
    except ConvergenceError as e:
        _drop_held_warnings()
        print(f"simfab: did not converge: {_one_line(e)}", file=sys.stderr)
        _debug_trace()
        return 1
    except KeyboardInterrupt as e:
        _drop_held_warnings()
        _release_quietly(e)
        print("simfab: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # internal failure: one line unless debugging
        _drop_held_warnings()
        print(f"simfab: internal error: {type(e).__name__}: {_one_line(e)}", file=sys.stderr)
        _debug_trace()
        return 1


_OUT_FLAG = {"render": "-o/--output or --out"}

#: Subcommands whose finished work stays on failure: a sweep resumes from the runs already in its table.
_KEEPS_PARTIAL = ("sweep",)


def _all_or_nothing(command: str, roots):
    """The run's outputs published on success only (:func:`simfab.io.outpaths.published_on_success`)."""
    if command in _KEEPS_PARTIAL:
        return contextlib.nullcontext()
    return published_on_success(roots, keep_on=(ValidationFailed,))  # a missed tolerance: its report stays


class _Interrupts:
    """Ctrl-C and SIGTERM (``kill``, a batch system's time limit) raise KeyboardInterrupt in the
    main thread, so the run's partial outputs are taken back (signals cannot be set elsewhere).

    Some libraries catch ``BaseException`` around their optional imports (trimesh, at over a hundred
    sites), which swallows an interrupt that lands in such an import: the run would go on and publish.
    So once a signal came, it is sent again every ``RESEND`` seconds until the interrupt has left the
    run (:meth:`run`); a repeat raises only where no KeyboardInterrupt is being handled (the clean-up
    it runs on its way out, such as closing a Dask cluster, is not broken), and a run that returns, or
    fails otherwise, after a swallowed interrupt ends as interrupted. From then on further signals are
    ignored, so the rollback that follows completes.
    ``with interrupts:`` holds the handlers around the rollback; ``with interrupts.run():`` wraps the
    run inside it.
    """

    RESEND = 0.2

    def __enter__(self):
        self._old, self._requested, self._left, self._resender = {}, False, threading.Event(), None
        if threading.current_thread() is threading.main_thread():
            self._old = {s: signal.signal(s, self._handle) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc):
        self._left.set()
        if self._resender is not None:
            self._resender.join()
        for s, h in self._old.items():
            signal.signal(s, h)
        return False

    def _handle(self, signum, frame):
        if self._left.is_set() or _handling_interrupt():  # rollback or clean-up on the interrupt's way out
            return
        if not self._requested:
            self._requested = True
            self._resender = threading.Thread(target=self._resend, name="simfab-interrupt", daemon=True)
            self._resender.start()
        raise KeyboardInterrupt

    def _resend(self):
        main_thread = threading.main_thread().ident
        while not self._left.wait(self.RESEND):
            signal.pthread_kill(main_thread, signal.SIGTERM)

    @contextlib.contextmanager
    def run(self):
        """The scope of the run itself: an interrupt that leaves it, or was swallowed in it, ends here."""
        try:
            yield
        except BaseException as e:
            self._left.set()
            if self._requested and not isinstance(e, KeyboardInterrupt):
                raise KeyboardInterrupt from e  # a failure after a swallowed interrupt: still interrupted
            raise
        self._left.set()
        if self._requested:
            raise KeyboardInterrupt


def _handling_interrupt() -> bool:
    """Whether the code a signal interrupted is handling a KeyboardInterrupt (``except``, ``finally``,
    ``__exit__``), directly or as the context of the exception it handles."""
    e = sys.exc_info()[1]
    while e is not None:
        if isinstance(e, KeyboardInterrupt):
            return True
        e = e.__context__
    return False


def _output_roots(args) -> list:
    """The folders the subcommand will write into (checked before it runs, then enforced)."""
    fn = getattr(args._module, "output_roots", None)
    return list(fn(args)) if fn is not None else [args.out]


#: Warnings held back while a subcommand runs - numeric ones (NumPy's ``RuntimeWarning``: invalid
#: value, divide by zero, overflow) and every "simfab...: warning: ..." line written to stderr: after a
#: successful run they are shown; on the error path they are dropped (shown only with
#: SIMFAB_DEBUG=1), so an error is the one line on stderr.
_HELD: list[str] = []

_WARNING_LINE = re.compile(r"simfab[\w ]*: warning: ")


class _HoldWarningLines:
    """Within the block, lines written to stderr that are simfab warnings go to ``_HELD``; everything
    else (progress, log lines) passes through at once."""

    def __enter__(self):
        self._stream, self._newline = sys.stderr, False
        sys.stderr = self
        return self

    def __exit__(self, *exc):
        sys.stderr = self._stream
        return False

    def write(self, text: str) -> int:
        if self._newline and text == "\n":  # print() writes its end separately
            self._newline = False
            return len(text)
        self._newline = False
        if _WARNING_LINE.match(text):
            _HELD.extend(line for line in text.splitlines() if line.strip())
            self._newline = not text.endswith("\n")
            return len(text)
        return self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings (e.g. mesh repairs) as one line on stderr, like simfab's own warnings;
    numeric ones (RuntimeWarning) are held back until the run's outcome is known (``_HELD``)."""
    text = _one_line(message) if isinstance(message, BaseException) else " ".join(str(message).split())
    text = f"simfab: warning: {text}"
    if isinstance(category, type) and issubclass(category, RuntimeWarning):
        _HELD.append(text)
    else:
        print(text, file=sys.stderr)


def _flush_held_warnings() -> None:
    for text in _HELD:
        print(text, file=sys.stderr)
    _HELD.clear()


def _drop_held_warnings() -> None:
    if os.environ.get("SIMFAB_DEBUG"):
        _flush_held_warnings()
    _HELD.clear()


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _release_quietly(e: BaseException) -> None:
    """Free what the frames of an interrupted run held, without reporting a destructor's failure: an
    interrupt can land inside a constructor (a MuJoCo renderer making its GL context), and the half-built
    object's destructor then fails; an interrupted run says one line (all of it with SIMFAB_DEBUG=1)."""
    if os.environ.get("SIMFAB_DEBUG"):
        return
    hook, sys.unraisablehook = sys.unraisablehook, lambda unraisable: None
    try:
        while e is not None:
            e.__traceback__, e = None, e.__cause__ or e.__context__
        gc.collect()
    finally:
        sys.unraisablehook = hook


def _debug_trace() -> None:
    if os.environ.get("SIMFAB_DEBUG"):
        import traceback

        traceback.print_exc()


def _report(result: dict | None, args) -> None:
    from simfab.cli._summary import print_summary
    from simfab.io.atomic import to_jsonable

    result = to_jsonable(result or {})
    if args.json:
        sys.stdout.write(json.dumps(result) + "\n")
        return
    sys.stdout.flush()
    action = next((getattr(args, a) for a in ("couple_command", "crowd_command", "validation")
                   if isinstance(getattr(args, a, None), str)), None)
    title = f"simfab {args.command}" + (f" {action}" if action else "")
    print_summary(result, units=getattr(args._module, "UNITS", None), title=title)


def entry() -> None:
    """Console-script entry point."""
    code = main()
    if code == 130 and not os.environ.get("SIMFAB_DEBUG"):  # what is freed as the interpreter exits, likewise
        sys.unraisablehook = lambda unraisable: None
    sys.exit(code)
