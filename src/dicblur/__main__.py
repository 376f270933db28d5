"""``python -m dicblur``: the command-line interface."""

from dicblur.cli import run

if __name__ == "__main__":
    run()
