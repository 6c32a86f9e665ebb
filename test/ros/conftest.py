"""Fixtures of the node tests: one DDS context (localhost, a random domain) per module, harnesses closed after."""
from __future__ import annotations

import gc
import os
import random
import time

import pytest
import rclpy
from node_harness import Harness


def collect_closed():
    """Collect closed nodes and executors now. rclpy prints the exception of a task it never retrieved (a
    callback cut short by the shutdown) when the task is collected: it must land in the test that closed them,
    not in a later test's captured output."""
    gc.collect()


@pytest.fixture(scope="module")
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=random.Random(os.getpid() ^ time.time_ns()).randint(1, 200))
    yield ctx
    rclpy.shutdown(context=ctx)
    collect_closed()


@pytest.fixture
def harness_factory(context, request):
    made = []

    def make(overrides=None, **kwargs):
        namespace = f"t{len(made)}_{request.node.name.replace('[', '_').replace(']', '').replace('-', '_')}"[:60]
        made.append(Harness(context, namespace.lower(), overrides or {}, **kwargs))
        return made[-1]

    yield make
    for harness in made:
        harness.close()
    made.clear()
    collect_closed()
