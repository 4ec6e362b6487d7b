"""Developer tools (run as scripts: python tools/<name>.py); importable as a package by the tests."""
