"""Command-line interface of dicblur.

The CLI is thin: each stage registers its commands from its own module; ``main`` is the
only place that configures logging and turns errors into one line on stderr and exit
code 2 (``--verbose`` adds the traceback).
"""

from __future__ import annotations

import functools
import logging
import os
import re
import sys
import traceback
import typing
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click
import typer
import typer.core

from ..errors import DicblurError, InputError

__all__ = ["app", "main", "run"]

# Commands in pipeline order (make a pattern, blur it, correlate, sweep, fit, plan; then the
# paper's studies), each with one full line in ``dicblur --help``.
PIPELINE: dict[str, str] = {
    "pattern": "Make speckle patterns, measure them, predict u_e(W) from one.",
    "noise": "Noise std (grey levels) from two images of a static scene.",
    "blur": "Motion-blur an image (paper's Algorithm 1), add camera noise.",
    "correlate": "Subset DIC of two images: the displacement field and its summary.",
    "campaign": "Run blur campaigns (serial or Dask), inspect and export them.",
    "calibrate": "The paper's blur sweep on one pattern, then the model fits.",
    "fit": "Fit the uncertainty models to campaign results (model JSON).",
    "predict": "Predict u_e at blur lengths, or from velocity, exposure, scale.",
    "plan": "Plan the exposure for a target u_e (optionally with a camera, or a page).",
    "track": "Track a high-speed recording: u, v and their sigma per point and frame.",
    "stereo": "Stereo DIC: calibrate a rig; 3-D shape, displacement and their sigma.",
    "pulse": "The paper's 1-D pulse study (Section V): Table II, Fig. 4-6.",
    "design": "Find the speckle pattern with the lowest u_e at your blur.",
    "reproduce": "Reproduce the paper: figures, tables, claims in one HTML report.",
}
_SUBCOMMANDS: dict[tuple[str, str], str] = {
    ("pattern", "generate"): "Write a random speckle pattern (plus its settings JSON).",
    ("pattern", "metrics"): "SSSIG, MIG, speckle size, contrast, static predictions.",
    ("pattern", "predict"): "Predict u_e(W) from the static image alone (no simulation).",
    ("stereo", "calibrate"): "Calibrate a stereo rig from checkerboard image pairs (OpenCV).",
    ("stereo", "track"): "Two recordings in: X, Y, Z, U, V, W3 and their sigma per point.",
    ("stereo", "plan"): "The exposure for a 3-D sigma target, and a better stereo angle.",
}


class _PipelineGroup(typer.core.TyperGroup):
    """The root group: lists the commands in :data:`PIPELINE` order with its one-liners."""

    # ``Any``: typer >= 0.20 vendors its own click, whose Context differs from click's.
    def list_commands(self, ctx: Any) -> list[str]:
        names = list(super().list_commands(ctx))
        order = list(PIPELINE)
        return sorted(
            names, key=lambda n: (order.index(n) if n in order else len(order), names.index(n))
        )

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None and cmd_name in PIPELINE:
            cmd.short_help = PIPELINE[cmd_name]
        if cmd is not None:
            _plain_usage(cmd)
            for name, sub in getattr(cmd, "commands", {}).items():
                if (cmd_name, name) in _SUBCOMMANDS:
                    sub.short_help = _SUBCOMMANDS[(cmd_name, name)]
        return cmd


def _plain_usage(cmd: Any) -> None:
    """Usage lines as ``dicblur blur [OPTIONS] IMAGE OUT``: typer writes required arguments
    as ``{image}``, which reads like a template placeholder. Only our commands change."""
    for param in getattr(cmd, "params", ()):
        if hasattr(param, "_usage_display_name"):

            def plain(p: Any = param) -> str:
                name = (p.metavar or p.name).upper()
                name = name if p.required else f"[{name}]"
                return name + ("..." if p.nargs != 1 else "")

            param._usage_display_name = plain
    for sub in getattr(cmd, "commands", {}).values():
        _plain_usage(sub)


app = typer.Typer(
    cls=_PipelineGroup,
    name="dicblur",
    help="Predict, measure and reduce the displacement uncertainty of 2-D DIC under motion blur.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version_callback(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"dicblur {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    verbose: bool = typer.Option(
        False, "--verbose", "-v", help="Show debug logging and full tracebacks on errors."
    ),
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version."
    ),
    max_pixels: str | None = typer.Option(
        None,
        "--max-pixels",
        metavar="N",
        help="Largest image read or generated, rows x cols px (default 1e8; also the "
        "DICBLUR_MAX_PIXELS environment variable). Larger images are refused before they "
        "are decoded or allocated.",
    ),
) -> None:
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        force=True,
    )
    if not verbose:
        # Dask logs cluster start-up and shutdown at INFO on its own handlers, configured
        # when distributed is imported (later, by campaign code): set it through Dask's
        # config environment, which that import reads and worker processes inherit.
        os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")
        for name in ("distributed", "dask"):
            logging.getLogger(name).setLevel(logging.WARNING)
    if max_pixels is not None:
        from ..io import max_pixels as _limit

        try:
            _limit(max_pixels)
        except DicblurError:
            raise DicblurError(
                f"--max-pixels={max_pixels}: expected a number of pixels >= 1, e.g. 4e8"
            ) from None
        # the environment reaches every reader, and Dask workers started from here
        os.environ["DICBLUR_MAX_PIXELS"] = max_pixels


# Stage command groups register themselves here (one import per stage).
from . import pattern as _pattern  # noqa: E402

_pattern.register(app)
from . import blur as _blur  # noqa: E402

_blur.register(app)
from . import campaign as _campaign  # noqa: E402

_campaign.register(app)
from . import pulse as _pulse  # noqa: E402

_pulse.register(app)
from . import correlate as _correlate  # noqa: E402

_correlate.register(app)
from . import models as _models  # noqa: E402

_models.register(app)
from . import design as _design  # noqa: E402

_design.register(app)

from . import reproduce as _reproduce  # noqa: E402

_reproduce.register(app)
from . import track as _track  # noqa: E402

_track.register(app)
from . import stereo as _stereo  # noqa: E402

_stereo.register(app)


_ABANDONED = re.compile(r"^coroutine '[^']*' was never awaited$")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    # a Ctrl-C inside a store's async I/O (zarr's event loop) leaves its coroutines
    # unawaited; their RuntimeWarning at collection says nothing to the user, whose one
    # line is the "interrupted" message (issue 15)
    if issubclass(category, RuntimeWarning) and _ABANDONED.match(str(message)):
        return
    print(f"warning: {message}", file=sys.stderr)


# API parameter names that a command exposes under another option name (used only when
# the command has that option).
_ALIASES = {
    "sigma": "noise",
    "noise_sigma": "noise",
    "shape": "size",
    "motion": "length",
    "start_speed": "start-speed",
    "max_pixels": "max-pixels",
    "results": "out",
    "out": "csv",
    # design: the API's bounds and distribution under their range options
    "speckle_size": "speckle-range",
    "density": "density-range",
    "softness": "softness-range",
    "weights": "blur-dist",
    "confirm_realisations": "confirm",
}
_NUMPY_REPR = re.compile(r"np\.(?:float|int|uint|complex|bool|str)[a-z_]*\d*\(([^()]*)\)")
_PARAM = re.compile(r"(?<![\w.\-('\"])(?:[A-Z][A-Za-z0-9]*\.)?([A-Za-z_][A-Za-z0-9_]*)=")
_LEADING = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*):")


@functools.lru_cache(maxsize=1)
def _root_command() -> Any:
    """The click tree of the app (built once: ~20 ms, and the app does not change)."""
    return typer.main.get_command(app)


def _command(args: Sequence[str]) -> Any:
    """The click command that ``args`` invoke (the root group if none)."""
    try:
        cmd: Any = _root_command()
    except Exception:  # pragma: no cover - the app is built at import
        return None
    it = iter(args)
    for tok in it:
        if tok == "--max-pixels":
            next(it, None)
            continue
        # typer may vendor its own click: duck-type groups and options
        sub = getattr(cmd, "commands", None)
        if isinstance(sub, dict) and tok in sub:
            cmd = sub[tok]
    return cmd


# a number with the unit the option's help gives: --noise 2GL, --blur 2px, --angle 90deg
_WITH_UNIT = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(px|GL|deg)\s*")
_UNIT_WORDS = {"px": (" px", "px)", "px."), "GL": ("grey level", " gl"), "deg": ("degree", "deg")}


def _is_number(param: Any) -> bool:
    """Whether an option takes numbers (``float``, ``int | None``, ``list[float]``)."""
    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    if ann is None:  # click without typer's descriptor
        return getattr(getattr(param, "type", None), "name", "") in ("float", "integer")

    def number(a: Any) -> bool:
        if a in (int, float):
            return True
        parts = typing.get_args(a)
        return bool(parts) and all(p is type(None) or number(p) for p in parts)

    return number(ann)


def strip_units(args: Sequence[str]) -> list[str]:
    """``args`` with the unit dropped from the value of a numeric option that is in that
    unit (``--noise 2GL`` -> ``--noise 2``: the unit syntax of the string options, for the
    plain-number ones). A unit the option is not in is left for the usage error."""
    cmd = _command(args)
    numeric: dict[str, str] = {}
    for param in getattr(cmd, "params", ()):
        if _is_number(param):
            help_text = f" {(getattr(param, 'help', '') or '').lower()}"
            for opt in getattr(param, "opts", ()):
                numeric[opt] = help_text
    out = list(args)
    for i, tok in enumerate(out):
        opt, eq, value = tok.partition("=")
        if eq and opt in numeric:
            j, text = i, value
        elif tok in numeric and i + 1 < len(out):
            j, text = i + 1, out[i + 1]
        else:
            continue
        m = _WITH_UNIT.fullmatch(text)
        if m and any(w in numeric[opt] for w in _UNIT_WORDS[m.group(2)]):
            out[j] = f"{opt}={m.group(1)}" if j == i else m.group(1)
    return out


def _is_path(param: Any) -> bool:
    """Whether an option takes a path (``Path``, ``Path | None``)."""
    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    return ann is Path or (ann is not None and Path in typing.get_args(ann))


def refuse_empty_paths(args: Sequence[str]) -> None:
    """An empty path option (``-o ""``) is refused: typer reads it as ``.``, so a command
    would write into the current folder."""
    paths = {
        opt
        for param in getattr(_command(args), "params", ())
        if _is_path(param)
        for opt in getattr(param, "opts", ())
    }
    for i, tok in enumerate(args):
        opt, eq, value = tok.partition("=")
        empty = (eq and opt in paths and not value.strip()) or (
            tok in paths and i + 1 < len(args) and not args[i + 1].strip()
        )
        if empty:
            name = opt if eq else tok
            raise InputError(f"{name}='': an empty path; give a file or folder name")


def _command_options(args: Sequence[str]) -> dict[str, str]:
    """{python parameter name: option as typed} of the command that ``args`` invoke."""
    cmd = _command(args)
    names: dict[str, str] = {"max_pixels": "--max-pixels"}
    for param in getattr(cmd, "params", ()):
        if getattr(param, "param_type_name", "") == "option" and param.name:
            long = [o for o in param.opts if o.startswith("--")]
            names[param.name] = (long or list(param.opts))[0]
    return names


def cli_message(text: str, args: Sequence[str]) -> str:
    """An API error message as the CLI user should read it: ``sigma=-1.0`` becomes
    ``--noise=-1.0`` (and a leading ``blur:`` becomes ``--blur:``) when the command has
    that option, numpy reprs become plain numbers, and the message is one line."""
    text = " ".join(_NUMPY_REPR.sub(r"\1", str(text)).split())
    opts = _command_options(args)

    def option(name: str) -> str | None:
        key = name if name in opts else _ALIASES.get(name, "").replace("-", "_")
        return opts.get(key)

    def repl(m: re.Match[str]) -> str:
        opt = option(m.group(1))
        return f"{opt}=" if opt else m.group(0)

    text = _PARAM.sub(repl, text)
    lead = _LEADING.match(text)
    if lead and option(lead.group(1)):
        text = f"{option(lead.group(1))}:{text[lead.end() :]}"
    return text


def _typed_value(param: Any, args: Sequence[str]) -> str | None:
    """The value the user typed for option ``param`` (the last one given), if any."""
    opts = tuple(getattr(param, "opts", ()) or ())
    if getattr(param, "param_type_name", "") != "option":
        return None
    value = None
    for i, tok in enumerate(args):
        if tok in opts and i + 1 < len(args):
            value = args[i + 1]
        elif "=" in tok and tok.split("=", 1)[0] in opts:
            value = tok.split("=", 1)[1]
    return value


def usage_line(exc: Any, args: Sequence[str]) -> str:
    """A click usage error (unknown option, missing argument, a value of the wrong type)
    as one line: ``error: <what>='<value>' ...; see 'dicblur blur --help'``."""
    msg = " ".join(str(exc.format_message()).split()).rstrip(".")
    value = _typed_value(getattr(exc, "param", None), args)
    if value is not None:
        msg = f"{msg} (got {value!r})"
        if any(ch in value for ch in "\u2212\u2013\u2014"):
            # pasted from a document: a typographic minus or dash is not a number's sign
            msg = f"{msg}, a typographic minus or dash: type the ASCII '-'"
    ctx = getattr(exc, "ctx", None)
    path = getattr(ctx, "command_path", None) or "dicblur"
    return f"error: {msg}; see '{path} --help'"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (default ``sys.argv[1:]``) and return the exit code.

    Exit codes: 0 success, 2 bad input or usage (one line on stderr), 130 interrupted.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    verbose = "--verbose" in args or "-v" in args
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning
    old_limit = os.environ.get("DICBLUR_MAX_PIXELS")
    try:
        refuse_empty_paths(args)
        rv = app(args=strip_units(args), prog_name="dicblur", standalone_mode=False)
        return rv if isinstance(rv, int) else 0
    except DicblurError as exc:
        if verbose:
            traceback.print_exc()
        print(f"error: {cli_message(str(exc), args)}", file=sys.stderr)
        return 2
    except (click.exceptions.Exit, typer.Exit) as exc:
        return int(getattr(exc, "exit_code", 0))
    except (click.exceptions.Abort, typer.Abort):
        print("aborted", file=sys.stderr)
        return 130
    except (click.ClickException, typer.TyperException) as exc:
        # Usage errors (bad option, missing argument). typer >= 0.20 vendors its own click,
        # so both exception families are caught.
        if type(exc).__name__ == "NoArgsIsHelpError":  # a bare group: its help
            exc.show()  # type: ignore[union-attr]
        else:  # one line, like every other bad input (click's own shows three)
            print(usage_line(exc, args), file=sys.stderr)
        return int(getattr(exc, "exit_code", 2) or 2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        if verbose:
            traceback.print_exc()
        print(
            "error: out of memory; use a smaller image or campaign (see dicblur --max-pixels)",
            file=sys.stderr,
        )
        return 2
    except OSError as exc:
        # the file system refused (disk full, permission, ...): not a dicblur bug
        if verbose:
            traceback.print_exc()
        print(f"error: {cli_message(str(exc), args)}", file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = old_show
        # --max-pixels applies to this invocation only (main may run many times in-process)
        if old_limit is None:
            os.environ.pop("DICBLUR_MAX_PIXELS", None)
        else:
            os.environ["DICBLUR_MAX_PIXELS"] = old_limit


def run() -> None:
    """Console-script entry point."""
    sys.exit(main())
