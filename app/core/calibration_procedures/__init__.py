"""The calibration procedures behind the wizard (numpy only, no Qt).

One purpose per module:

- :mod:`.stillness`: is the sensor still? (window variance against the datasheet noise)
- :mod:`.gyro_bias`: the gyro-bias step (state machine, bias and uncertainty)
- :mod:`.poses`: automatic capture of still poses, with rejection reasons
- :mod:`.accel_fit`: six-position (known faces) and ellipsoid (free poses) fits
- :mod:`.tilt_comparison`: tilt error before and after a calibration
- :mod:`.level_reference`: tare and the reversal procedure
- :mod:`.static_stats`: mean, std, min/max and spread of the angles over 20 s
- :mod:`.profiles`: calibration profiles per device, as JSON files

Feed these with *uncalibrated* blocks (``convert_raw_block(raw)``, or the pipeline running
the identity calibration): the fits estimate the raw sensor's errors. The results combine
into an :class:`app.core.calibration.SensorCalibration` via :meth:`AccelFit.to_calibration`.
"""

from app.core.calibration_procedures.accel_fit import (
    AccelFit,
    CalibrationFitError,
    fit_ellipsoid,
    fit_free_poses,
    fit_known_orientations,
    fit_six_position,
)
from app.core.calibration_procedures.gyro_bias import (
    GyroBiasCalibration,
    GyroBiasResult,
    GyroBiasState,
    gyro_bias_from_samples,
)
from app.core.calibration_procedures.level_reference import (
    ReversalResult,
    TareReference,
    reversal,
    reversal_first_order,
    reversal_from_angles,
)
from app.core.calibration_procedures.poses import (
    FACE_DIRECTIONS,
    FACE_HINTS,
    FACES,
    FREE,
    MAX_FACE_TILT_DEG,
    SIX_POSITION,
    CapturedPose,
    CaptureEvent,
    CaptureState,
    FaceTilt,
    PoseCapture,
    face_tilts,
    identify_face,
)
from app.core.calibration_procedures.profiles import (
    CalibrationProfile,
    ProfileCorruptError,
    ProfileDeviceMismatchError,
    ProfileError,
    ProfileNotFoundError,
    ProfileStore,
    ProfileVersionError,
    SensorSettings,
    make_profile,
)
from app.core.calibration_procedures.static_stats import (
    AngleStats,
    StaticStatistics,
    StaticStatisticsResult,
)
from app.core.calibration_procedures.stillness import SensorNoise, StillnessDetector
from app.core.calibration_procedures.tilt_comparison import (
    TiltComparison,
    TiltErrors,
    calibrate_accel,
    compare_poses,
    compare_tilt,
    worsening,
)

__all__ = [
    "FACES",
    "FACE_DIRECTIONS",
    "FACE_HINTS",
    "FREE",
    "MAX_FACE_TILT_DEG",
    "SIX_POSITION",
    "AccelFit",
    "AngleStats",
    "CalibrationFitError",
    "CalibrationProfile",
    "CaptureEvent",
    "CaptureState",
    "CapturedPose",
    "FaceTilt",
    "GyroBiasCalibration",
    "GyroBiasResult",
    "GyroBiasState",
    "PoseCapture",
    "ProfileCorruptError",
    "ProfileDeviceMismatchError",
    "ProfileError",
    "ProfileNotFoundError",
    "ProfileStore",
    "ProfileVersionError",
    "ReversalResult",
    "SensorNoise",
    "SensorSettings",
    "StaticStatistics",
    "StaticStatisticsResult",
    "StillnessDetector",
    "TareReference",
    "TiltComparison",
    "TiltErrors",
    "calibrate_accel",
    "compare_poses",
    "compare_tilt",
    "face_tilts",
    "fit_ellipsoid",
    "fit_free_poses",
    "fit_known_orientations",
    "fit_six_position",
    "gyro_bias_from_samples",
    "identify_face",
    "make_profile",
    "reversal",
    "reversal_first_order",
    "reversal_from_angles",
    "worsening",
]
