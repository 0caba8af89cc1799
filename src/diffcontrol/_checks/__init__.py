"""The task checks behind ``diffcontrol.checks``: shapes (``shapes``), the contract under
``jit``, ``vmap`` and ``grad`` (``contract``), parity with Gymnasium (``parity``)."""
