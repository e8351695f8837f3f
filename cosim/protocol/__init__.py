"""The wire protocol (specified in docs/protocol.md).

- ``wire``: field types of msgpack messages, checked and converted; ``messages``: request and reply
  schemas, encoding and total decoding; ``keys``: a run's key expressions; ``service``: one request
  payload to one reply payload for a runtime. None of these imports a transport.
- ``transport``: Zenoh sessions, the subsim-side server, the coordinator-side remote handle.
"""
