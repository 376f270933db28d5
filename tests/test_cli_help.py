"""CLI consistency (issue 16): commands in pipeline order with a full one-line help,
plain usage lines, the same -o/--out everywhere."""

from __future__ import annotations

import re

import pytest
import typer.main

from dicblur.cli import PIPELINE, app, main


def commands() -> dict[str, object]:
    """Every command of the CLI by its path ('blur', 'campaign run', ...)."""
    root = typer.main.get_command(app)
    out: dict[str, object] = {}

    def walk(cmd, path):
        subs = getattr(cmd, "commands", None)
        if subs:
            for name, sub in subs.items():
                walk(sub, [*path, name])
        else:
            out[" ".join(path)] = cmd

    walk(root, [])
    return out


def test_help_lists_every_command_in_pipeline_order_with_a_full_line(capsys):
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    listing = text[text.index("Commands:") :].splitlines()[1:]
    names = [
        line.split()[0] for line in listing if line.startswith("  ") and not line.startswith("   ")
    ]
    assert names == list(PIPELINE)
    for line in listing:
        assert not line.rstrip().endswith("..."), line  # nothing cut short
    top = {path.split()[0] for path in commands()}
    assert top == set(PIPELINE)


@pytest.mark.parametrize("path", sorted(commands()))
def test_usage_lines_have_no_template_placeholders(path, capsys):
    assert main([*path.split(), "--help"]) == 0
    usage = capsys.readouterr().out.splitlines()[0]
    assert usage.startswith(f"Usage: dicblur {path}")
    assert not re.search(r"[{}]", usage), usage


def test_every_output_option_is_dash_o_and_double_dash_out():
    for path, cmd in commands().items():
        for param in cmd.params:
            if (
                param.name == "out"
                and getattr(param, "opts", None)
                and param.param_type_name == "option"
            ):
                assert {"-o", "--out"} <= set(param.opts), path


def test_abandoned_coroutine_warning_after_an_interrupt_is_not_shown(capsys):
    """Seen in CI: a SIGINT during a campaign's cluster start-up left zarr's
    coroutines unawaited, and their RuntimeWarnings followed the one "interrupted" line."""
    from dicblur.cli import _show_warning

    _show_warning(RuntimeWarning("coroutine '_runner' was never awaited"), RuntimeWarning, "f", 1)
    assert capsys.readouterr().err == ""
    _show_warning(UserWarning("the exposure is long"), UserWarning, "f", 1)
    assert capsys.readouterr().err == "warning: the exposure is long\n"
