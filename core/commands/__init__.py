"""The command-line commands of ``python -m zoopraxis``: argument parsing, reading and writing
files, progress; no numerics of their own. May import every stage of core, never the add-on
(the bake command lives in ``addon/command_bake.py``).
"""
