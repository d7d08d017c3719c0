"""`python -m spinefarm ...` is the `spinefarm` command."""

from spinefarm.cli.main import main

if __name__ == "__main__":
    raise SystemExit(main())
