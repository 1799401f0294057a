"""The command line, ``stratawalk`` (:func:`planner.cli.main.main`)."""
