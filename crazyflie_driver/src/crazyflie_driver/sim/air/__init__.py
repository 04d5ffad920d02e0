"""Between host and world: the fake Crazyradio and its USB side, the media, the world server's wire, UDP."""
