"""Under CI (CI=true) a test whose tool or shared data is missing fails; elsewhere it skips."""
import pytest

import ci_needs


@pytest.mark.parametrize("ci,outcome", [(True, pytest.fail.Exception), (False, pytest.skip.Exception)])
def test_missing_fails_under_ci_and_skips_elsewhere(monkeypatch, ci, outcome):
    monkeypatch.setattr(ci_needs, "CI", ci)
    with pytest.raises(outcome, match="../shared/models"):
        ci_needs.missing("the shared real models (../shared/models)")
    ran = []
    absent = ci_needs.needs(False, "the shared real models (../shared/models)")(lambda: ran.append(1))
    with pytest.raises(outcome, match="../shared/models"):
        absent()
    assert ran == []
    present = ci_needs.needs(True, "x")(lambda: ran.append(1))
    present()
    assert ran == [1]
