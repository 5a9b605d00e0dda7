"""Sub-commands of the flagsim command, one module each (see flagsim.cli.COMMANDS)."""
