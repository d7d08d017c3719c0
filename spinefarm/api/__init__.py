"""Read-only HTTP status API: `from spinefarm.api.app import create_app`."""
