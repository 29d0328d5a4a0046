"""Runs and campaigns: configuration, seeding, executors, result store."""
