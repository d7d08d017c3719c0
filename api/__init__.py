"""Read-only HTTP status API: `from api.app import create_app`."""
