"""``python -m v2c``: the `v2c` command."""

from v2c.cli import main

main(prog_name="v2c")
