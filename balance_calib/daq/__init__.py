"""A data acquisition device on /balance/raw (balance_daq's core, without rclpy).

parameters.py (the node's table, the checked settings), framing.py (bytes -> records: text lines,
binary records), samples.py (records -> checked, counted, converted, stamped samples), health.py
(the /diagnostics status), transports.py (serial, tcp, udp), reader.py (the device's thread).
"""
