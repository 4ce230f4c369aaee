"""CLI commands: spike (registered on viform.cli.app.cli)."""
