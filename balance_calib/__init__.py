"""balance_calib: six-component wind-tunnel balance calibration after NAL TM-663.

The pipeline, one sub-package per arrow (data flows one way):

    simulation/ or bags/  ->  refit/ (load points, zero points, tare)  ->  fit/  ->  diagnosis/
                          ->  accuracy/ (residuals, sigma, tables)  ->  calibration file  ->
                                                                        nodes/

model/ holds the math models of TM-663 §2 (and any other term list) and their inverse;
tare/ the calibration body of §6-7; tunnel_axes.py the wind-on transforms of §10.
Nothing outside nodes/ imports rclpy.
"""

__version__ = '0.1.0'
