"""``python -m roshan`` = the ``roshan`` console script."""

from roshan.cli import main

main()
