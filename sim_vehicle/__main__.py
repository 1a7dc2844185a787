import sys

from sim_vehicle.cli import main

sys.exit(main())
