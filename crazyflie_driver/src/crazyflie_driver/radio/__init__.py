"""The Crazyradio and the links over it; never imports the simulator."""
