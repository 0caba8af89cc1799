"""The built-in systems' overrides of what the layers do with their tasks (evaluate, draw,
animate), registered with those layers (``tasks._hooks``). Nothing imports these modules by
name but the task registry (``tasks.plugin``): they sit on top of the layers, as a user's own
task file does."""
