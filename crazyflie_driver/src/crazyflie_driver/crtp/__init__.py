"""CRTP packets, URIs and the C types on the wire (no I/O)."""
