"""Other tools' formats: import (x-IMU3, EuRoC/Kalibr, generic CSV) and export."""
