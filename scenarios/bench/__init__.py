"""The benchmarks behind ``mrslam bench``: ``sim`` (with ``irsim``, the IR-SIM peer), ``slam``,
``explore`` and ``merge/``. Only the CLI imports them; the library never does."""
