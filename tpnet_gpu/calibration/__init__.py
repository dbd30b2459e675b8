"""Field calibration of the quad's extrinsic corrections from the pairs' 2-D correlation peaks
(docs/calibration.md): ``calibrate`` (robust LMA or gradient descent through ``tpnet_gpu.differentiable``),
the gauge (``gauge``), and the frame-edge misalignment between two rigs (``edge_misalignment``)."""

from tpnet_gpu.calibration.fit import CalibrationConfig, CalibrationResult, calibrate
from tpnet_gpu.calibration.measure import Frame
from tpnet_gpu.calibration.model import edge_misalignment, gauge, observable_part

__all__ = ["CalibrationConfig", "CalibrationResult", "Frame", "calibrate", "edge_misalignment", "gauge",
           "observable_part"]
