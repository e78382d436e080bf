"""Sub-command modules; cli.py adds every module here that defines `command`."""
