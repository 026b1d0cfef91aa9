"""The command line's commands, one module each (``cli.py`` holds the parser and the dispatch).

A front end like ``cli.py``: core never imports it. Only the standard library is imported at module
level here too (each command imports core inside its function), so ``--help`` loads no numpy.
"""
