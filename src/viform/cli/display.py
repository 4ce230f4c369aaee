"""CLI commands: display (registered on viform.cli.app.cli)."""
