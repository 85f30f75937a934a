"""Device I/O. No Qt here: drivers are plain Python objects a worker thread drives.

Open a device by URL with :func:`drivers.registry.open_device`; list what can be connected with
:func:`drivers.registry.available_devices`.
"""
