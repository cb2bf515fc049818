"""A simulated LRAUV that speaks MAVLink 2 over UDP like ArduSub SITL.

``world`` (true currents from a forecast), ``dynamics`` (pure physics), ``autopilot``
(ArduSub's modes, GUIDED targets and failsafes as pure logic), ``endpoint`` (the UDP/MAVLink
edge and the speedup clock), ``cli`` (``lrauv sim``); ``demo`` runs it with the executive.
"""
