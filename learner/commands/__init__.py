"""The learner's commands (``train``, ``evaluate``, ``render``, ``control``) and the argument parsing they share:
each module gives the dispatcher ``add_arguments(parser)`` and ``run(args)``; the work is done elsewhere."""
