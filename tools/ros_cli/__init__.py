"""`launchless_scripts/ros`: the few `ros2` CLI habits this package's users need, over rclpy.

A development stand-in, not part of the installed balance_calib package: there is no ros2cli in
the wheel-only venv (ROS 2 comes from PyPI wheels). This is not a re-implementation of it, only
the everyday verbs, with the same spelling:

    ros param list NODE                 ros2 param list NODE
    ros param get NODE NAME             ros2 param get NODE NAME
    ros param set NODE NAME VALUE       ros2 param set NODE NAME VALUE   (VALUE in YAML: 3, 0.5,
                                                                         true,
                                        "[a.mcap, b.mcap]"; kept in the parameter's current type)
    ros param describe NODE NAME ...    ros2 param describe NODE NAME    (type, description,
                                                                         constraints)
    ros param dump NODE                 ros2 param dump NODE             (a params-file YAML)
    ros topic list                      ros2 topic list -t
    ros topic info TOPIC [-v]           ros2 topic info TOPIC [-v]       (-v: each endpoint's QoS)
    ros topic echo TOPIC [--count N]    ros2 topic echo TOPIC            (YAML documents, ---;
                                                                         --once = --count 1)
    ros topic hz TOPIC [--duration S]   ros2 topic hz TOPIC
    ros service list                    ros2 service list -t
    ros service call SERVICE            ros2 service call SERVICE std_srvs/srv/Trigger
    ros node list                       ros2 node list
    ros node info NODE                  ros2 node info NODE              (publishers, subscribers,
                                                                          services)
    ros bag info BAG                    ros2 bag info BAG                 (no DDS: reads the files)
    ros bag record OUT [TOPIC ...]      ros2 bag record -s mcap -o OUT    (balance_recorder)
    ros bag play BAG [BAG ...]          ros2 bag play BAG                 (bridge_publisher replay)

One module per verb (param, topic, service, node, bag); the graph session and discovery waits in
session.py, value conversions in values.py; cli.py holds the one table of sub-commands the parser
is built from. The lists (topic, service, node) wait until discovery has settled: until what the
graph shows has not changed for SETTLE_S, at most --timeout. A reader that goes away
(`... | head`) ends the output quietly.

Parameters go through the node's rcl_interfaces services (~/list_parameters, ~/get_parameters,
~/set_parameters), as ros2 param does. Exit status 0 on success, 1 when the node, topic or service
does not answer within --timeout, 2 on bad arguments; errors are one line on stderr.
"""
