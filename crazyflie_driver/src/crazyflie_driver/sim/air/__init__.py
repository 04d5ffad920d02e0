"""Between host and world: the fake Crazyradio, the media, the world server and its wire, UDP."""
