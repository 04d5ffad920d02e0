"""The simulated Crazyflie's radio side: nRF link, CRTP ports, parameters, logs, memories, TOCs, decoders."""
