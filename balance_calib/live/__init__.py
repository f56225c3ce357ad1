"""The live side without rclpy: what the nodes compute (calibrated wrench, tare, diagnostics,
simulated load profiles and publication timelines), so it is testable without DDS.
"""
