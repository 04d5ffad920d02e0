"""PollPacer: polls paced to the log packets due, so a shared dongle is not spent on empty acks."""
from __future__ import annotations

from crazyflie_driver.server.log_plan import PlannedBlock, log_packet_rate
from crazyflie_driver.server.poll_pacer import PollPacer


def fly(pacer: PollPacer, periods, seconds: float, round_trip: float = 0.0023, phase: float = 0.0):
    """A Crazyflie producing one packet per block period (world starts at ``phase``), polled as the
    pacer says; returns (polls, packets fetched, worst age of a packet when fetched, left queued)."""
    produced = sorted(phase + p * k for p in periods for k in range(1, int(seconds / p) + 1))
    queue, i, now, polls, fetched, worst = [], 0, 0.0, 0, 0, 0.0
    while now < seconds:
        now += round_trip
        while i < len(produced) and produced[i] <= now:
            queue.append(produced[i])
            i += 1
        polls += 1
        got = 0
        if queue:
            worst = max(worst, now - queue.pop(0))
            fetched += 1
            got = 1
        now += pacer.after_round_trip(got, now)
    return polls, fetched, worst, len(queue)


def test_without_logging_it_is_a_keepalive():
    p = PollPacer(0.010, rate=0.0)
    assert p.after_round_trip(0, 1.0) == 0.010
    assert p.after_round_trip(0, 1.01) == 0.010


def test_fixed_topics_fetched_with_few_empty_polls():
    # imu every 10 ms plus two 100 ms blocks: 120 packets/s. Fetching one packet per poll and
    # polling again after each (the former scheme) took ~180 polls/s at a 2.3 ms round trip.
    periods = (0.010, 0.100, 0.100)
    polls, fetched, worst, left = fly(PollPacer(0.010, log_packet_rate([PlannedBlock(10), PlannedBlock(100),
                                                                        PlannedBlock(100)])), periods, 10.0)
    assert fetched >= 1195 and left <= 2
    assert polls / 10.0 < 150                # at most ~25 % empty polls
    assert worst < 0.035                     # nothing waits long in the Crazyflie's queue


def test_a_backlog_is_drained_at_once():
    p = PollPacer(0.010, rate=100.0, now=0.0)
    assert p.after_round_trip(0, 0.0) == 0.010
    # the link was busy for 100 ms: ~10 packets are due, each fetch is followed at once
    waits = [p.after_round_trip(1, 0.100 + 0.001 * k) for k in range(5)]
    assert waits == [0.0] * 5


def test_a_standing_backlog_is_cleared_every_drain_interval():
    p = PollPacer(0.010, rate=100.0, now=0.0)
    p.after_round_trip(0, 0.0)
    # packets arrive exactly when due, so the count says nothing is left: paced, not immediate
    assert p.after_round_trip(1, 0.010) > 0.0
    # but after DRAIN_INTERVAL without an empty ack the pacer polls until one comes back empty
    assert p.after_round_trip(1, PollPacer.DRAIN_INTERVAL + 0.001) == 0.0
    assert p.after_round_trip(0, PollPacer.DRAIN_INTERVAL + 0.003) == 0.010


def test_bursts_are_bounded():
    p = PollPacer(0.010, rate=1000.0, now=0.0)
    waits = [p.after_round_trip(1, 1.0) for _ in range(PollPacer.MAX_BURST + 1)]
    assert waits[:PollPacer.MAX_BURST] == [0.0] * PollPacer.MAX_BURST
    assert waits[-1] > 0.0


def test_swarm_mode_polls_about_once_per_pose_packet():
    """A swarm Crazyflie (keep-alive period 100 ms, the radio budget's floor; sparse pacing) with the
    10 Hz onboard pose block: about one poll per packet, whatever the block's phase and the round trip,
    against two with the eager pacing and about 80 polls/s with the 10 ms keep-alive."""
    rate = log_packet_rate([PlannedBlock(100)])
    for phase in (0.003, 0.05, 0.097):
        for round_trip in (0.0023, 0.010):
            polls, fetched, worst, left = fly(PollPacer(0.100, rate, margin=PollPacer.SPARSE_MARGIN), (0.100,), 10.0,
                                              round_trip=round_trip, phase=phase)
            assert fetched >= 98 and left <= 1
            assert polls <= 1.15 * fetched
            assert worst < 0.100 + 2 * round_trip      # a packet waits at most about one period
    eager = fly(PollPacer(0.100, rate), (0.100,), 10.0, phase=0.003)
    assert eager[0] >= 1.9 * eager[1]
    assert fly(PollPacer(0.010, rate), (0.100,), 10.0, phase=0.003)[0] / 10.0 >= 80     # 10 ms + the round trip
    assert fly(PollPacer(0.100, margin=PollPacer.SPARSE_MARGIN), (), 10.0)[0] / 10.0 <= 10.0   # nothing logged


def test_replies_queued_ahead_of_the_log_are_drained_at_once():
    """A broadcast high-level command repeated 15 times leaves 15 replies in each Crazyflie's downlink
    queue, ahead of its log packets. Polls that fetch them are not empty: the pacer polls again at once,
    so the pose packets behind them come out a round trip or so late, not after a second of sparse
    keep-alives (each reply taken for an empty ack)."""
    rate = log_packet_rate([PlannedBlock(100)])
    pacer = PollPacer(0.100, rate, margin=PollPacer.SPARSE_MARGIN)
    produced = [0.003 + 0.1 * k for k in range(1, 60)]
    queue, now, worst, polls = [], 0.0, 0.0, 0
    replies_at, replies = 2.0, 15
    while now < 6.0:
        now += 0.0023
        if replies and now >= replies_at:
            queue[:0] = ["reply"] * replies        # the firmware's replies go out before later log data
            replies = 0
        while produced and produced[0] <= now:
            queue.append(produced.pop(0))
        polls += 1
        logged = others = 0
        if queue:
            item = queue.pop(0)
            if item == "reply":
                others = 1
            else:
                logged = 1
                worst = max(worst, now - item)
        now += pacer.after_round_trip(logged, now, others)
    assert not queue
    assert worst < 0.100 + 0.05                     # a period and the few polls the replies took
    assert polls <= 1.2 * 59 + 15 + 10
