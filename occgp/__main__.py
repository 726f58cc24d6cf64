"""``python -m occgp``: the ``occgp`` command (:func:`occgp.cli.main`)."""

from occgp.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
