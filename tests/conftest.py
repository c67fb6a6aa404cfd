"""Shared fixtures. Tests import the installed package (``pip install -e ".[test]"``)."""

from __future__ import annotations
