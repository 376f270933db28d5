"""Command-line interface of dicblur.

The CLI is thin: each stage registers its commands from its own module; ``main`` is the
only place that configures logging and turns errors into one line on stderr and exit
code 2 (``--verbose`` adds the traceback).
"""

from __future__ import annotations

import logging
import os
import sys
import traceback
import warnings
from collections.abc import Sequence

import click
import typer

from ..errors import DicblurError

__all__ = ["app", "main", "run"]

app = typer.Typer(
    name="dicblur",
    help="Predict, measure and reduce the displacement uncertainty of 2-D DIC under motion "
    "blur.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version_callback(value: bool) -> None:
    if value:
        from .. import __version__

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


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (default ``sys.argv[1:]``) and return the exit code.

    Exit codes: 0 success, 2 bad input or usage (one line on stderr), 130 interrupted.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    verbose = "--verbose" in args or "-v" in args
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        rv = app(args=args, prog_name="dicblur", standalone_mode=False)
        return rv if isinstance(rv, int) else 0
    except DicblurError as exc:
        if verbose:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (click.exceptions.Exit, typer.Exit) as exc:
        return int(getattr(exc, "exit_code", 0))
    except (click.exceptions.Abort, typer.Abort):
        print("aborted", file=sys.stderr)
        return 130
    except (click.ClickException, typer.TyperException) as exc:
        # Usage errors (bad option, missing argument). typer >= 0.20 vendors its own click,
        # so both exception families are caught.
        exc.show()  # type: ignore[union-attr]
        return int(getattr(exc, "exit_code", 2) or 2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = old_show


def run() -> None:
    """Console-script entry point."""
    sys.exit(main())
