"""Sub-commands of `v2c`; each module defines `command` (a click command). Heavy imports go inside the function."""
