"""``python -m vehicle_sim [sim] --forecast F.nc --start LON,LAT ...``: the simulated vehicle."""

from vehicle_sim.cli import main

raise SystemExit(main())
