"""The joints' health over time: the catalogue of every analysis (SQLite / PostgreSQL), batch
re-analysis into it, trends and alarms, the fleet, and the condition monitor of a running machine.
"""
