"""The Zenoh transport: sessions, the subsim-side server and the coordinator-side remote handle.

The only part of ``cosim.protocol`` that imports zenoh; messages, keys and the service are
transport-free.
"""
