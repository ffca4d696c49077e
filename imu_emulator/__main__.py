import sys

from imu_emulator.cli import main

sys.exit(main())
