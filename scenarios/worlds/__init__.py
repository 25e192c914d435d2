"""The worlds: ``buildings`` (hand-made floor plans), ``procedural`` (seeded generated ones)
and ``catalog``, the named scenarios registered under the ``mrslam.scenarios`` entry point."""
