"""Commands taken by the tick loop (ros/runtime.py: PolledGroup, take_all) with real rclpy.

Oracle: what a publisher in another context sent, in the order it sent it. While the group is
polled the executor runs none of its callbacks and every message waits for take_all; once it is
not, the executor delivers them again.
"""

from __future__ import annotations

import os
import threading
import time

import rclpy
import waiting
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray
from std_msgs.msg import String as Text

from vjm_ros.ros.runtime import PolledGroup, Spinner, take_all

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])


def wait_for(predicate, timeout=30.0, what="condition"):
    """:func:`waiting.wait_for` with this file's hang guard, 30.0 s."""
    waiting.wait_for(predicate, timeout, what)


def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
    return ctx


def test_polled_messages_wait_for_take_all_in_order_of_reception_then_callbacks_resume():
    rx_ctx, tx_ctx = context(), context()
    try:
        rx = rclpy.create_node("polled_rx", context=rx_ctx)
        tx = rclpy.create_node("polled_tx", context=tx_ctx)
        polled = threading.Event()
        polled.set()
        group = PolledGroup(polled.is_set)
        called = []
        numbers = rx.create_subscription(Float64MultiArray, "/polled/numbers",
                                         lambda m: called.append(m), 10, callback_group=group)
        words = rx.create_subscription(Text, "/polled/words", lambda m: called.append(m), 10,
                                       callback_group=group)
        pub_numbers = tx.create_publisher(Float64MultiArray, "/polled/numbers", 10)
        pub_words = tx.create_publisher(Text, "/polled/words", 10)
        executor = SingleThreadedExecutor(context=rx_ctx)
        executor.add_node(rx)
        spinner = Spinner(executor).start()
        try:
            # matched from both sides: a message sent before the reader knows the writer arrives
            # late (repaired), after the ones sent later
            wait_for(lambda: all(e.get_subscription_count() for e in (pub_numbers, pub_words))
                     and all(s.get_publisher_count() for s in (numbers, words)), what="discovery")
            sent = []
            for i in range(4):  # alternating topics: the order must survive the two queues
                pub_numbers.publish(Float64MultiArray(data=[float(i)]))
                pub_words.publish(Text(data=f"w{i}"))
                sent += [float(i), f"w{i}"]
                time.sleep(0.02)
            got = []
            handlers = [(numbers, "numbers"), (words, "words")]

            def taken():
                got.extend(take_all(handlers))
                return len(got) >= len(sent)

            wait_for(taken, what="the polled messages")
            assert called == []  # the executor left them alone
            values = [m.data[0] if h == "numbers" else m.data for h, m in got]
            assert values == sent
            assert all((h == "numbers") == isinstance(m, Float64MultiArray) for h, m in got)
            polled.clear()  # not polled: the executor's callbacks deliver again
            pub_words.publish(Text(data="late"))
            wait_for(lambda: called, what="a callback")
            assert [m.data for m in called] == ["late"]
            assert take_all(handlers) == []
        finally:
            spinner.stop()
            executor.shutdown()
    finally:
        rclpy.try_shutdown(context=rx_ctx)
        rclpy.try_shutdown(context=tx_ctx)
