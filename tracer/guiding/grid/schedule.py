"""Algorithm 1 of Zhu et al. 2021, the schedule of the histogram guides (`grid`, `photon`).

A 1-spp pilot (unguided, its vertices start the grid), training iterations t = 1, 2, ... of
2^t N_c spp, each followed by the guide's update, while they fit (with spp: while the final pass
gets at least as many samples as the iteration; with a time budget: while twice the estimated
cost fits in the budget and the iteration ends within `train_budget` of it, and while the guide's
training_done() says no), then the guide's
finish_training() (where it may switch itself off), then the final passes with what the budget
has left. The image combines the training iterations and the
final passes weighted by the inverse of each one's mean pixel variance (the pilot is not used);
where the guide switched itself off, the training iterations are left out too: they were guided
where guiding does not pay, and their variance, estimated from a few spp where fireflies are
rare, weighs them in too much (`veach-mis`, docs/failures.md).
"""


def algorithm1(session, guide):
    """Run Algorithm 1 for `guide` (a Guide with iterations, spp_init, train_budget) in `session`.
    guide.training says how training went (training_record)."""
    guide.training = training_record(guide.iterations)
    session.phase("pilot")
    session.run_pass(session.new_film("pilot"), 1, "pilot", learn=True)
    for t in range(1, guide.iterations + 1):
        if guide.training_done():
            _stopped(guide, "converged", "the guide predicted that more training would not pay (mixing)")
            break
        n = guide.spp_init * 2 ** t
        if session.time is None:
            if session.sample0 + 2 * n > session.spp:
                _stopped(guide, "spp", f"iteration {t}'s {n} spp would leave the final pass fewer of the "
                                       f"{session.spp} spp")
                break  # the final pass gets at least as many samples as this iteration
        else:
            last = session.passes[-1]
            est = (last["time"] / last["spp"]) * n + 2.0 * last.get("time_update", 0.0)
            elapsed = session.elapsed()
            if elapsed + 2.0 * est > session.time or elapsed + est > guide.train_budget * session.time:
                share = guide.train_budget * session.time
                if elapsed + est > share:
                    _stopped(guide, "train_budget", _share_used(session, guide, t, est, share))
                else:
                    _stopped(guide, "time", f"iteration {t} (about {est:.2f} s) would leave less than as much "
                                            f"for the final passes of the {session.time:g}-s budget")
                break
        film = session.new_film("train")
        session.phase(f"train {t}/{guide.iterations}")
        session.run_pass(film, n, "train", learn=True)
        guide.training["trained"] = t
    if guide.finish_training() or not guide.training_in_image:
        session.leave_out_training()
    session.ctx.guide_state = guide.state()  # what the final passes sample from
    session.final_passes(guide.split_plan(session.training_films(), session.ctx.crop))


def training_record(iterations):
    """What a render's stats say of Algorithm 1's training (stats guide_stats.training): the
    iterations asked for, those trained after the pilot, and, where fewer were trained, `stopped`
    (converged, spp, train_budget or time) and `why` in words; stopped is None after every
    iteration, or when the render was interrupted during training."""
    return {"iterations": int(iterations), "trained": 0, "stopped": None, "why": ""}


def _stopped(guide, reason, why):
    guide.training.update(stopped=reason, why=why)


def _share_used(session, guide, t, est, share):
    """Why training ended at the training share: what the pilot, iterations and updates so far took."""
    done = "the pilot" + (f" and {t - 1} iteration(s)" if t > 1 else "")
    updates = sum(p.get("time_update", 0.0) for p in session.passes)
    return (f"the training share was used up: {done} took {session.elapsed():.2f} s ({updates:.2f} s of it "
            f"updating the guide), and iteration {t} (about {est:.2f} s) would end past train_budget "
            f"{guide.train_budget:g} x {session.time:g} s = {share:.2f} s")
