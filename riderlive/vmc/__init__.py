"""VMC out: the rider (and the horse) to VMC marionettes over OSC/UDP.

- :mod:`~riderlive.vmc.osc`: OSC 1.0 encoding (pure);
- :mod:`~riderlive.vmc.performer`: poses -> one bundle per frame (pure; the mapping);
- the UDP sender the service runs (``serve --vmc``) is :mod:`~riderlive.service.vmc_out` (it reads tick records).

The protocol, the mapping per engine and where sending runs: ``docs/vmc.md``.
"""
