"""Algorithm 1 of Zhu et al. 2021, the schedule of the histogram guides (`grid`, `photon`) and `ppg`.

A 1-spp pilot (unguided, its vertices start the grid), training iterations t = 1, 2, ... of
2^t N_c spp, each followed by the guide's update, while they fit (with spp: while the final pass
gets at least as many samples as the iteration; with a time budget: while the iteration, at the
last pass's measured seconds per spp with its update, ends within `train_budget` of the budget
and leaves the final passes at least as long again, and while the guide's training_done() says
no), then the guide's finish_training() (where it may switch itself off), then the final passes
with what the budget has left. With a time budget, the first iteration that does not fit runs
shortened to the spp that do, where the guide finds them worth an update (Guide.min_last_spp),
so the training share is used whatever the machine's timing draws (see _fit). The image combines
the training iterations and the final passes weighted by the inverse of each one's mean pixel
variance (the pilot is not used); where the guide switched itself off, the training iterations
are left out too: they were guided where guiding does not pay, and their variance, estimated from
a few spp where fireflies are rare, weighs them in too much (`veach-mis`, docs/failures.md).
"""


def algorithm1(session, guide, start=1, last=None):
    """Run Algorithm 1 for `guide` (a Guide with iterations, spp_init, train_budget) in `session`.
    guide.training says how training went (training_record); guide.train_spp is set to each
    training pass's spp before it runs. With `last` (the session's pass entry of the latest pass
    the guide learned from: a pilot, or training iterations before `start`, as guiding.auto's
    trials run them) the pilot is not run again and training starts at iteration `start`."""
    if last is None:
        guide.training = training_record(guide.iterations)
        session.phase("pilot")
        guide.train_spp = 1
        session.run_pass(session.new_film("pilot"), 1, "pilot", learn=True)
        last = session.passes[-1]
    elif guide.training is None:
        guide.training = training_record(guide.iterations)
    for t in range(start, guide.iterations + 1):
        if guide.training_done():
            _stopped(guide, "converged", "the guide predicted that more training would not pay (mixing)")
            break
        n = guide.spp_init * 2 ** t
        last_stage = False
        if session.time is None:
            if session.sample0 + 2 * n > session.spp:
                _stopped(guide, "spp", f"iteration {t}'s {n} spp would leave the final pass fewer of the "
                                       f"{session.spp} spp")
                break  # the final pass gets at least as many samples as this iteration
        else:
            n, last_stage = _fit(session, guide, t, n, last)
            if n == 0:
                break
        film = session.new_film("train")
        session.phase(f"train {t}/{guide.iterations}")
        guide.train_spp = n
        session.run_pass(film, n, "train", learn=True)
        last = session.passes[-1]
        guide.training["trained"] = t
        guide.training["spp"].append(n)
        if last_stage:
            break
    if guide.finish_training() or not guide.training_in_image:
        session.leave_out_training()
    session.ctx.guide_state = guide.state()  # what the final passes sample from
    session.final_passes(guide.split_plan(session.training_films(), session.ctx.crop))


def _fit(session, guide, t, n, last):
    """With a time budget, the spp iteration t runs and whether it is the last: (n, False) while the
    whole iteration fits, else (n', True) with n' the spp that fit (0: training stops here).

    An iteration's cost is predicted from the guide's last pass (`last`, its session entry): its
    seconds per spp plus its update's seconds per spp (an update's work, photons and records, grows
    with the iteration's spp), times n. It fits while it ends within train_budget x the budget and
    leaves the final passes at least as long again. Where it does not fit, it runs shortened to the
    spp that do (so the training share is used whatever the machine's timing draws), if that is at
    least guide.min_last_spp(previous spp), else training ends."""
    per_spp = (last["time"] + last.get("time_update", 0.0)) / last["spp"]
    elapsed = session.elapsed()
    share = guide.train_budget * session.time
    room = min(share - elapsed, 0.5 * (session.time - elapsed))
    if n * per_spp <= room:
        return n, False
    n_fit = min(n - 1, int(room / per_spp)) if room > 0 else 0
    reason = "train_budget" if share - elapsed <= 0.5 * (session.time - elapsed) else "time"
    bound = (f"train_budget {guide.train_budget:g} x {session.time:g} s = {share:.2f} s" if reason == "train_budget"
             else f"half the {session.time:g}-s budget left for the final passes")
    need = guide.min_last_spp(last["spp"])
    if n_fit >= need:
        _stopped(guide, reason, f"iteration {t} ran {n_fit} of its {n} spp (about {n_fit * per_spp:.2f} s, "
                                f"{per_spp:.3f} s per spp with its update) to end within {bound}")
        guide.training["shortened"] = True
        return n_fit, True
    if reason == "train_budget":
        head = f"the training share was used up: {_spent(session, t)}, and iteration {t} (about {n * per_spp:.2f} s)"
    else:
        head = f"iteration {t} (about {n * per_spp:.2f} s)"
    _stopped(guide, reason, f"{head} would end past {bound}; the {n_fit} spp that fit are fewer than the {need} "
                            f"worth an update")
    return 0, True


def training_record(iterations):
    """What a render's stats say of Algorithm 1's training (stats guide_stats.training): the
    iterations asked for, those trained after the pilot, their spp, whether the last was
    shortened to fit the budget, and, where fewer than asked were trained in full, `stopped`
    (converged, spp, train_budget or time) and `why` in words; stopped is None after every
    iteration, or when the render was interrupted during training."""
    return {"iterations": int(iterations), "trained": 0, "spp": [], "shortened": False, "stopped": None, "why": ""}


def _stopped(guide, reason, why):
    guide.training.update(stopped=reason, why=why)


def _spent(session, t):
    """What the pilot, iterations and updates so far took, in words."""
    done = "the pilot" + (f" and {t - 1} iteration(s)" if t > 1 else "")
    updates = sum(p.get("time_update", 0.0) for p in session.passes)
    return f"{done} took {session.elapsed():.2f} s ({updates:.2f} s of it updating the guide)"
