"""Placeholder until this plugin type lands."""
