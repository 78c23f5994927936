"""The applications built on the layers below: the ``gyro-sim`` command (``cli*``), the benchmark (``bench*``), the
parameter sweeps (``sweep*``), the phase portrait, the API reference (``api_docs``) and the pytest kit for a user's
controller (``testing``). The top layer: may import every layer (``ros``, ``io``, ``engine``, ``averaging``,
``scenes``, ``compiled``, ``physics``, ``common``; of ``ros`` only what needs no rclpy at import: ``ros.index``,
``ros.launch``); nothing imports an app.
"""
