"""Reading and writing the bags of the topic contract, outside the node graph's algorithms.

* `bagio`: the message types, reading messages from a bag, images out of messages.
* `bagplay`: a bag as a source of timed messages (topics, rates, faults) for the player node.
"""
