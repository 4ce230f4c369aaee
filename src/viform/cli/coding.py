"""CLI commands: coding (registered on viform.cli.app.cli)."""
