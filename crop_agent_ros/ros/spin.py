"""Client-side rclpy helpers shared by the agent node, the Gymnasium bridge, the benchmark and the tests.

Measured on rclpy 7.1.6: ``rclpy.spin_until_future_complete`` leaves tasks behind and slows down with
every call, so service calls here use ``call_async`` and spin the caller's own executor with
``spin_once`` until the future is done. Discovery of a fresh peer can take 2-3 s: wait for services and
subscribers (``wait_for_service``, ``wait_for_subscribers``), never a fixed sleep.
"""

from __future__ import annotations

import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor


class ServiceTimeout(TimeoutError):
    pass


def spin_until(executor, condition, timeout: float, what: str = "condition", step: float = 0.05) -> None:
    """Spin ``executor`` one callback at a time until ``condition()`` is true, else ServiceTimeout."""
    deadline = time.monotonic() + timeout
    while not condition():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise ServiceTimeout(f"timed out after {timeout:.1f} s waiting for {what}")
        executor.spin_once(timeout_sec=min(step, remaining))


def call(executor, client, request, timeout: float = 10.0):
    """A service call: call_async, then spin ``executor`` until the response arrives."""
    future = client.call_async(request)
    try:
        spin_until(executor, future.done, timeout, what=f"a response from {client.srv_name}")
    except ServiceTimeout:
        client.remove_pending_request(future)
        future.cancel()
        raise
    return future.result()


def wait_for_service(executor, client, timeout: float = 15.0) -> None:
    """Spin while waiting for a service server to be discovered."""
    spin_until(executor, client.service_is_ready, timeout, what=f"service {client.srv_name}", step=0.02)


def wait_for_subscribers(executor, publisher, timeout: float = 15.0, count: int = 1) -> None:
    spin_until(executor, lambda: publisher.get_subscription_count() >= count, timeout,
               what=f"a subscriber on {publisher.topic_name}", step=0.02)


class PrivateRos:
    """A private rclpy Context with one node and its own single-threaded executor.

    Several can live in one process (tests, the bridge inside a training script) without touching
    the global default context. ``close()`` destroys the node and shuts the context down.
    """

    def __init__(self, node_name: str, args: list[str] | None = None, namespace: str | None = None,
                 parameter_overrides=None, start_parameter_services: bool = False):
        self.context = Context()
        rclpy.init(context=self.context, args=args)
        # a client node: no parameter services by default (fewer entities: a cheaper spin_once)
        self.node = rclpy.create_node(node_name, context=self.context, namespace=namespace,
                                      parameter_overrides=parameter_overrides,
                                      start_parameter_services=start_parameter_services)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, condition, timeout: float, what: str = "condition") -> None:
        spin_until(self.executor, condition, timeout, what)

    def call(self, client, request, timeout: float = 10.0):
        return call(self.executor, client, request, timeout)

    def close(self) -> None:
        if getattr(self, "_closed", False):
            return
        self._closed = True
        try:
            self.executor.remove_node(self.node)
            self.executor.shutdown(timeout_sec=0.1)
            self.node.destroy_node()
        finally:
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> "PrivateRos":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
