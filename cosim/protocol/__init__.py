"""Wire protocol (msgpack messages) and its Zenoh transport. Specified in docs/protocol.md."""
