"""Reusable studies: each module's ``main(argv)`` is the command behind ``studies/<name>.py``.

They sit above the orchestrators (they run identifications, loops and the benchmark and tabulate them) and
read the checkout's ``studies/`` configs and ``data/`` by default. ``regenerate`` lists and runs the commands
that rebuild ``docs/results``.
"""
