"""First contact with a bench: what this machine can record from, and the self-test's checks.
"""
