"""CLI commands: highspeed (registered on viform.cli.app.cli)."""
