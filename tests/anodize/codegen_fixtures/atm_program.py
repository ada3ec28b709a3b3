"""The ATM session written against its generated typed states (checked by mypy --strict)."""

from __future__ import annotations

import atmsession_a
import atmsession_c


def client(start: atmsession_c.Initial) -> atmsession_c.End:
    match start.send_login(42).offer():
        case atmsession_c.State1Err(end):
            return end
        case atmsession_c.State1Ok(menu):
            pass
    menu = menu.select_deposit(100)
    match menu.select_withdraw(30).offer():
        case atmsession_c.State4Ok(cash, menu):
            assert cash == 30
        case atmsession_c.State4Fail(menu):
            pass
    balance, menu = menu.select_balance().recv_int()
    assert balance == 70
    return menu.select_quit()


def machine(start: atmsession_a.Initial) -> atmsession_a.End:
    account, deciding = start.recv_login()
    if account < 0:
        return deciding.select_err()
    balance = 0
    menu = deciding.select_ok()
    while True:
        match menu.offer():
            case atmsession_a.State2Deposit(amount, menu):
                balance += amount
            case atmsession_a.State2Withdraw(amount, answering):
                if amount <= balance:
                    balance -= amount
                    menu = answering.select_ok(amount)
                else:
                    menu = answering.select_fail()
            case atmsession_a.State2Balance(answering_balance):
                menu = answering_balance.send_int(balance)
            case atmsession_a.State2Quit(end):
                return end
