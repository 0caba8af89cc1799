"""The built-in systems that are their own folders (the trebuchet, the swing-ups) and the
built-in tasks' overrides of what the layers do with them (evaluate, draw, fit, record, their
RL baselines: ``zoo``), registered with those layers (``tasks._hooks``). Nothing imports these
modules by name but the task registry (``diffcontrol._registry``, lazily): they sit on top of
the layers, as a user's own task file does."""
