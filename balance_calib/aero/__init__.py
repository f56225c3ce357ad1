"""From calibrated loads to aerodynamic coefficients (TM-663 §10.3-10.4), without rclpy.

axes.py           the axis conventions and their signs, written down once
model_file.py     config/models/NAME.yaml: reference lengths, moment reference centre, weight,
                  deflection
weight_tare.py    the model's weight and CG by attitude, fitted from a wind-off sweep (load space)
deflection.py     sting and balance deflection under load, added to the support's angles
coefficients.py   moment transfer to the moment reference centre, body and wind-axis coefficients
held_points.py    held attitudes found in a stream of samples, averaged into data points
run.py            a wind-on run, held point by held point: tare tracking, reduction, uncertainty
"""
