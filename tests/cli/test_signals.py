"""Ctrl-C and SIGTERM as a request to stop (biped_opt/cli/signals.py), with real signals sent to
this process."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from biped_opt.cli.signals import stop_requested


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_deferred_signal_sets_the_event_and_calls_back_off_the_main_thread(sig):
    called = []
    with stop_requested() as stop:
        stop.defer(lambda: called.append(threading.current_thread().name))
        assert not stop.is_set()
        os.kill(os.getpid(), sig)
        assert stop.wait(5.0)  # (the relay thread wakes the waiter)
        deadline = time.monotonic() + 5.0
        while not called and time.monotonic() < deadline:
            time.sleep(0.001)
    assert called == ["stop-request"]  # once, and not from inside the handler
    assert signal.getsignal(sig) is not None and not isinstance(
        signal.getsignal(sig), type(stop._handle))  # (the previous handler is back)


def test_a_signal_before_defer_reaches_the_callback_given_later():
    called = []
    with stop_requested() as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.is_set()  # the handler's flag, before any relay
        stop.defer(lambda: called.append(1))
    assert called[:1] == [1]


def test_while_starting_up_a_signal_still_raises_keyboard_interrupt():
    with pytest.raises(KeyboardInterrupt):
        with stop_requested(interrupt=True) as stop:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # (interrupted at once)
    assert stop.is_set()

