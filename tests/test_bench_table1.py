"""bench.table1: the seed paper's Table 1 layout from convergence records (stand-in records)."""
import json

from bench import table1


def _record(scene, method, seed, relmse, spp=100, memory=0):
    return {"scene": scene, "method": method, "seed": seed, "budget": "time", "time_budget": 30.0, "spp": spp,
            "time_learning": 1.0, "update_s": 0.5, "inference_s": 0.0, "guide_memory_bytes": memory,
            "metrics": {"relMSE": relmse}}


def test_ratios_are_pt_over_the_method_with_the_papers_beside(tmp_path):
    """PT's mean relMSE over the method's mean (not the mean of per-seed ratios): PT 2 and 4 over
    photon 0.5 and 1.0 is 4.00, beside the paper's Gauss-Best 65 on veach-ajar; NEE on against
    bsdf; a scene the paper has no column for gets no bracket; a missing records file is exit 2."""
    recs = [_record("veach-ajar", "bsdf/path:nee=0", 0, 2.0), _record("veach-ajar", "bsdf/path:nee=0", 1, 4.0),
            _record("veach-ajar", "photon/path:nee=0", 0, 0.5), _record("veach-ajar", "photon/path:nee=0", 1, 1.0),
            _record("veach-ajar", "bsdf", 0, 0.3), _record("veach-ajar", "photon", 0, 0.1, memory=3 << 20),
            _record("own", "bsdf/path:nee=0", 0, 1.0), _record("own", "photon/path:nee=0", 0, 0.25)]
    with open(tmp_path / "records.jsonl", "w") as f:
        f.write("\n".join(json.dumps(r) for r in recs) + "\n")
    assert table1.main([str(tmp_path)]) == 0
    text = (tmp_path / "table1.md").read_text()
    assert "| veach-ajar | 4.00 (65) |" in text
    assert "| own | 4.00 |" in text
    assert "| veach-ajar | 3.00 |" in text  # NEE on: 0.3 / 0.1
    assert "| veach-ajar | `photon` | 0.1 (0.1) | 100 | 1.5 | 3.0 |" in text
    assert table1.main([str(tmp_path / "nothing")]) == 2
